"""Session-wide GPU resources and the cache folder."""

from __future__ import annotations

import contextlib
import os
from pathlib import Path

import bpy

from ..core import noise
from ..core.errors import NubisError
from ..render.engine import CloudGPU
from ..render.gpu_context import ensure_gpu_context

_EXT_PACKAGE = __package__.rsplit(".", 2)[0]  # "bl_ext.<repo>.nubis" when installed, "nubis_addon"'s parent otherwise
_gpu: dict[int, CloudGPU] = {}


def cache_dir() -> Path:
    """Where generated noise volumes are cached: never inside the extension's own folder."""
    override = os.environ.get("NUBIS_CACHE_DIR")
    if override:
        path = Path(override)
    elif _EXT_PACKAGE.startswith("bl_ext."):
        path = Path(bpy.utils.extension_path_user(_EXT_PACKAGE, path="cache", create=True))
    else:
        # Run as a plain module (python -m nubis_addon): the folder the installed extension would use.
        path = Path(bpy.utils.user_resource("EXTENSIONS", path=os.path.join(".user", "user_default", "nubis", "cache")))
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise NubisError(
            f"cannot create the cache folder '{path}' ({err.strerror}): set NUBIS_CACHE_DIR to a writable folder"
        ) from None
    return path


def cloud_gpu(seed: int) -> CloudGPU:
    """The GPU inputs for a noise seed, generated or loaded from the cache once per session."""
    ensure_gpu_context()
    if seed not in _gpu:
        _gpu.clear()  # one texture set at a time keeps GPU memory inside Guerrilla's 20 MB budget
        _gpu[seed] = CloudGPU(noise.load_or_generate(cache_dir(), seed))
    return _gpu[seed]


def free() -> None:
    _gpu.clear()


_own_renders = [0]


@contextlib.contextmanager
def own_render():
    """Around a render Nubis makes itself (the Cycles reference of the baked VDB, the benchmark's EEVEE
    frame): the F12 clouds (blender/scene_render.py) stay out of it."""
    _own_renders[0] += 1
    try:
        yield
    finally:
        _own_renders[0] -= 1


def own_render_running() -> bool:
    return _own_renders[0] > 0
