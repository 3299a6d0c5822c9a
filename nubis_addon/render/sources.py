"""Where the GLSL lives, and how the stages are assembled from it."""

from __future__ import annotations

import re
from functools import cache
from pathlib import Path

SHADER_DIR = Path(__file__).resolve().parents[2] / "shaders"

# Library files in dependency order; every stage that samples clouds gets all of them.
CLOUD_LIBS = (
    "nubis_common_lib.glsl",
    "nubis_vdb_lib.glsl",
    "nubis_density_lib.glsl",
    "nubis_lighting_lib.glsl",
    "nubis_motion_lib.glsl",
    "nubis_march_lib.glsl",
)


_GENERATED = re.compile(r"^NUBIS_GENERATED\((\w+)\)$", re.MULTILINE)


@cache
def read_shader(name: str) -> str:
    """A shader of shaders/ by file name (an absolute path reads a stage from elsewhere, e.g. the tests'),
    each `NUBIS_GENERATED(what)` line replaced by the source render/uniforms.py generates for it."""
    path = Path(name)
    text = (path if path.is_absolute() else SHADER_DIR / name).read_text(encoding="utf-8")
    return _GENERATED.sub(lambda m: _generated(m.group(1)), text)


def _generated(what: str) -> str:
    from . import uniforms  # the block's layout; it imports nothing of this module

    makers = {"nubis_layer": uniforms.layer_source}
    if what not in makers:
        raise ValueError(f"NUBIS_GENERATED({what}): nothing generates '{what}' (render/sources.py)")
    return makers[what]()


def assemble(*names: str) -> str:
    return "\n".join(f"/* ---- {n} ---- */\n{read_shader(n)}" for n in names)
