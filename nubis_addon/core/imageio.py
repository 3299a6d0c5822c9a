"""Image files: EXR holds scene-linear premultiplied RGBA as 32-bit float; PNG is display-referred.

EXR is written as float32, not half: half float ends at 65504, which a sky at the documented maximum
strength (1e5) passes, and the overflow would be written as infinity. float32 holds every value the
renderers produce, so nothing is clamped; a value that is still not finite (NaN from a fault) is
refused with the count of such pixels rather than written.

Both are written atomically. The PNG goes through Blender's own OCIO configuration so that a
viewport render and a Cycles render of the same scene get the same view transform.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from . import bundled
from .errors import NubisError
from .fsutil import atomic_path, shown, sync_to_disk

IMAGE_SUFFIXES = (".png", ".exr")


def read_image(path: str | os.PathLike) -> np.ndarray:
    """Return float32 pixels, shape (height, width, channels), top row first."""
    oiio = bundled.oiio()
    buf = oiio.ImageBuf(str(path))
    if buf.has_error:
        raise NubisError(f"cannot read the image '{path}' ({buf.geterror().strip()}): check the file")
    px = buf.get_pixels(oiio.FLOAT)
    if px is None or buf.has_error:
        raise NubisError(f"cannot read the image '{path}': the file is damaged")
    return np.asarray(px, dtype=np.float32)


def composite_over(rgba: np.ndarray, background: np.ndarray | tuple[float, float, float]) -> np.ndarray:
    """Premultiplied RGBA over an opaque background (a colour or an image)."""
    bg = np.broadcast_to(np.asarray(background, dtype=np.float32), rgba.shape[:2] + (3,))
    out = np.empty(rgba.shape[:2] + (4,), np.float32)
    out[..., :3] = rgba[..., :3] + bg * (1.0 - rgba[..., 3:4])
    out[..., 3] = 1.0
    return out


def to_display(rgba: np.ndarray, view_transform: str, ocio_config: str | None, look: str = "None") -> np.ndarray:
    """Scene-linear Rec.709 to sRGB display values through Blender's OCIO config; sRGB OETF without it."""
    oiio = bundled.oiio()
    if ocio_config and Path(ocio_config).is_file():
        buf = oiio.ImageBuf(oiio.ImageSpec(rgba.shape[1], rgba.shape[0], rgba.shape[2], oiio.FLOAT))
        buf.set_pixels(oiio.ROI(), np.ascontiguousarray(rgba, dtype=np.float32))
        out = oiio.ImageBufAlgo.ociodisplay(buf, "sRGB", view_transform, "Linear Rec.709", colorconfig=ocio_config)
        if not out.has_error:
            disp = np.asarray(out.get_pixels(oiio.FLOAT), np.float32)
            if rgba.shape[2] == 4:
                disp[..., 3] = rgba[..., 3]
            return np.clip(disp, 0.0, 1.0)
    lin = np.clip(rgba[..., :3], 0.0, None)
    srgb = np.where(lin <= 0.0031308, lin * 12.92, 1.055 * np.power(lin, 1 / 2.4) - 0.055)
    out = np.concatenate([srgb, rgba[..., 3:]], axis=-1) if rgba.shape[2] == 4 else srgb
    return np.clip(out, 0.0, 1.0)


def write_image(path: str | os.PathLike, pixels: np.ndarray) -> Path:
    """Write float pixels (H, W, C), top row first: EXR as 32-bit float, PNG as 8-bit. Atomic."""
    oiio = bundled.oiio()
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in IMAGE_SUFFIXES:
        raise NubisError(f"cannot write '{path}': image outputs must end in .png or .exr")
    pixels = np.ascontiguousarray(pixels, dtype=np.float32)
    bad = int(np.count_nonzero(~np.isfinite(pixels)))
    if bad:
        raise NubisError(
            f"refusing to write '{path}': {bad} of its {pixels.size} values are NaN or infinite (an internal "
            "fault, not a setting): run again with NUBIS_DEBUG=1 and report it"
        )
    h, w, c = pixels.shape
    fmt = oiio.FLOAT if suffix == ".exr" else oiio.UINT8
    spec = oiio.ImageSpec(w, h, c, fmt)
    if suffix == ".exr":
        spec.attribute("compression", "zip")
    with atomic_path(path) as tmp:
        out = oiio.ImageOutput.create(str(tmp))
        if out is None or not out.open(str(tmp), spec):
            raise NubisError(f"cannot write '{path}' ({oiio.geterror().strip()}): check the folder's permissions")
        ok = out.write_image(pixels)
        closed = out.close()  # the PNG writer flushes most of the file only here
        if not (ok and closed):
            raise NubisError(f"writing '{shown(path)}' failed ({out.geterror().strip()}): check the free disk space")
        _check_written(tmp, path, (h, w, c))
    return path


def _check_written(tmp: Path, path: Path, shape: tuple[int, int, int]) -> None:
    """The staged file on disk (fsync), then its header and its last row read back: a writer that ran out
    of disk space without saying so leaves a file cut short, which fails there at the latest (one row in
    memory, not a second copy of a 16384-pixel image)."""
    sync_to_disk(tmp, path)
    oiio = bundled.oiio()
    inp = oiio.ImageInput.open(str(tmp))
    whole = False
    if inp is None:
        oiio.geterror()  # retrieved, so OpenImageIO does not print it at exit
    else:
        spec = inp.spec()
        if (spec.height, spec.width, spec.nchannels) == shape:
            whole = inp.read_scanline(shape[0] - 1, 0, oiio.FLOAT) is not None and not inp.has_error
        inp.close()
    if not whole:
        raise NubisError(f"writing '{shown(path)}' failed (the file came out incomplete): check the free disk space")
