"""Where the GLSL lives, and how the stages are assembled from it."""

from __future__ import annotations

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


@cache
def read_shader(name: str) -> str:
    """A shader of shaders/ by file name (an absolute path reads a stage from elsewhere, e.g. the tests')."""
    path = Path(name)
    return (path if path.is_absolute() else SHADER_DIR / name).read_text(encoding="utf-8")


def assemble(*names: str) -> str:
    return "\n".join(f"/* ---- {n} ---- */\n{read_shader(n)}" for n in names)
