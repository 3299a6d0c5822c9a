"""The ranges the program can serve, checked before any work with a message that says what to do.

One table for presets (presets.py), the command line and scenes loaded from .blend files, so the
three agree. No bpy here.
"""

from __future__ import annotations

import math
import unicodedata
from collections.abc import Sequence

from .errors import NubisError
from .tomlfmt import toml_value

# Blender's frame numbers stop at -1048574 and 1048574 (its MAXFRAME): frame_set clamps anything beyond.
FRAME_RANGE = (-1048574, 1048574)
SAMPLES_RANGE = (1, 65536)
BOUNCES_RANGE = (0, 1024)  # Cycles' own limit on volume bounces
SIZE_RANGE = (4, 16384)
PASSES_RANGE = (1, 1024)
REDRAWS_RANGE = (1, 4096)  # preview's viewport redraws per frame
PREVIEW_FRAMES_MAX = 100000  # frames one preview draws
ORBIT_MAX = 360.0  # degrees preview's camera may turn per frame, either way
VOXEL_MAX = 10000.0  # metres: the bake_voxel_size setting's maximum (core/schema.py)
# metres: below a centimetre the box's voxel count overflows the arithmetic before the memory estimate can
# name a size that fits; clouds need nothing near it (the finest bakes use metres).
VOXEL_MIN = 0.01
# Positions (camera, storms, field centre) within 10,000 km of the origin: the GPU gets float32
# offsets from the camera, and the view rays a float64 inverse that stays well conditioned there.
POSITION_MAX = 1e7
# pixels per side of an image layer: twice the finest field (4096) is all a layer can give, and decoding
# a bigger one costs 20 bytes a pixel (Blender's bytes and the float copy composited) before it is scaled.
LAYER_IMAGE_MAX = 8192
MAX_FIELD_LAYERS = 128  # field layers per scene; each costs one full-resolution pass (estimate below)


def check_int(flag: str, value: int | None, lo: int, hi: int, unit: str = "") -> None:
    """A whole-number command-line option within [lo, hi]; ``flag`` is how the user wrote it."""
    if value is None or lo <= value <= hi:
        return
    raise NubisError(f"{flag} {value} is out of range: use a whole number between {lo} and {hi}{unit}")


def check_orbit(flag: str, value: float | None) -> None:
    if value is not None and not (math.isfinite(value) and abs(value) <= ORBIT_MAX):
        raise NubisError(f"{flag} must be a number of degrees between -{ORBIT_MAX:g} and {ORBIT_MAX:g}, not {value}")


def check_voxel_size(flag: str, value: float | None) -> None:
    if value is None:
        return
    if not math.isfinite(value) or value <= 0:
        raise NubisError(f"{flag} must be a positive number of metres, not {value:g}")
    if value > VOXEL_MAX:
        raise NubisError(f"{flag} {value:g} is out of range: use a voxel edge of at most {VOXEL_MAX:g} metres")
    if value < VOXEL_MIN:
        raise NubisError(f"{flag} {value:g} is out of range: use a voxel edge of at least {VOXEL_MIN:g} metres")


# A noise target below 0.5 % of the luminance would take tens of thousands of samples.
NOISE_TARGET_RANGE = (0.5, 50.0)


def check_noise_target(flag: str, value: float | None) -> None:
    """A noise target in percent of the luminance."""
    lo, hi = NOISE_TARGET_RANGE
    if value is None or (math.isfinite(value) and lo <= value <= hi):
        return
    raise NubisError(f"{flag} {value:g} is out of range: use a percentage between {lo:g} and {hi:g}")


def check_position(what: str, xyz: Sequence[float], fix: str) -> None:
    """A position in metres: finite and within POSITION_MAX of the origin on every axis."""
    if all(math.isfinite(v) and abs(v) <= POSITION_MAX for v in xyz):
        return
    where = "[" + ", ".join(f"{float(v):g}" for v in xyz) + "]"  # float32 coordinates, shown as written
    raise NubisError(f"{what} is at {where} m, beyond the {POSITION_MAX:g} m from the origin Nubis can render: {fix}")


def check_count(what: str, count: int, most: int, fix: str) -> None:
    if count > most:
        raise NubisError(f"{what}: {count} given, but a scene holds at most {most}: {fix}")


def check_text(where: str, text: str) -> None:
    """A name or other text a setting holds, free of control characters: a NUL (which Blender drops when
    it stores the text), an escape code or a line break would end up in image and object names and on the
    console. ``where`` names the setting."""
    bad = next((c for c in text if unicodedata.category(c) == "Cc"), None)
    if bad is not None:
        raise NubisError(
            f"{where} {toml_value(text)} holds the control character U+{ord(bad):04X}: use printable characters only"
        )
