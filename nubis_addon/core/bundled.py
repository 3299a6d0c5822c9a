"""Reach the OpenVDB and OpenImageIO modules that ship inside Blender, without importing bpy.

Inside a Blender executable they are already importable. The bpy wheel keeps them in
``bpy/<version>/python/lib/python3.X/site-packages``, which is not on sys.path
(docs/platform-notes.md#openvdb-and-openimageio-in-the-bpy-wheel).
We never vendor or pip-install a second copy.
"""

from __future__ import annotations

import importlib
import importlib.util
import sys
from pathlib import Path
from types import ModuleType

from .errors import NubisError


def _add_blender_site_packages() -> None:
    spec = importlib.util.find_spec("bpy")
    if spec is None or not spec.origin:
        return
    root = Path(spec.origin).parent
    pyver = f"python{sys.version_info.major}.{sys.version_info.minor}"
    for candidate in sorted(root.glob(f"*/python/lib/{pyver}/site-packages")):
        if str(candidate) not in sys.path:
            sys.path.append(str(candidate))


def _import(name: str, what: str) -> ModuleType:
    try:
        return importlib.import_module(name)
    except ImportError:
        _add_blender_site_packages()
    try:
        return importlib.import_module(name)
    except ImportError:
        raise NubisError(
            f"the {what} module '{name}' is missing from this Python ({sys.version.split()[0]}): run Blender 4.5 or "
            f"newer, or its bpy wheel (pip install bpy, 4.5 or newer), which ships it"
        ) from None


def openvdb() -> ModuleType:
    return _import("openvdb", "OpenVDB")


def oiio() -> ModuleType:
    return _import("OpenImageIO", "OpenImageIO")
