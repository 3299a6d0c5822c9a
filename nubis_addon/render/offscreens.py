"""Float offscreens of the GPU module: made (or refused with a size to try), drawn into step by step, read back
as numpy arrays; and a stepped piece of work run to its end."""

from __future__ import annotations

from collections.abc import Callable, Iterable

import gpu
import numpy as np

from ..core.errors import NubisError


def new_offscreen(width: int, height: int):
    """A float offscreen (with a depth buffer) of this size, or a NubisError with a size to try."""
    return _gpu_image(lambda: gpu.types.GPUOffScreen(width, height, format="RGBA32F"), width, height)


def _gpu_image(make: Callable, width: int, height: int):
    """`make()`'s float GPU image of this size, or a NubisError with a smaller size to try."""
    try:
        return make()
    except Exception as err:  # Blender raises a plain error when the GPU refuses the texture
        mb = width * height * 16 / 2**20
        raise NubisError(
            f"the GPU could not hold a {width}x{height} float image ({mb:.0f} MB): render smaller, for example "
            f"{max(4, width // 2)}x{max(4, height // 2)}, or on a GPU with more memory ({err})"
        ) from None


def check_offscreen(width: int, height: int) -> None:
    """Whether the GPU can hold a float image of this size: a NubisError with a size to try if not."""
    new_offscreen(width, height).free()


def draw_offscreen(width: int, height: int, draw: Callable[[], None]) -> np.ndarray:
    """Run `draw` into a cleared float offscreen of this size; its pixels, bottom row first."""
    return run_steps(draw_offscreen_steps(width, height, [draw]))


def draw_offscreen_steps(width: int, height: int, draws: Iterable[Callable[[], None]]):
    """`draws` one after another into a cleared float offscreen of this size, as a generator that yields
    the fraction done after each and returns the pixels, bottom row first. The interface's modal operators
    run one draw per timer tick, with the offscreen unbound in between so Blender can redraw its windows.
    Closing the generator frees the offscreen."""
    offscreen = new_offscreen(width, height)
    try:
        with offscreen.bind():
            gpu.state.active_framebuffer_get().clear(color=(0.0, 0.0, 0.0, 0.0))
        draws = list(draws)
        for i, draw in enumerate(draws):
            with offscreen.bind():
                gpu.state.blend_set("NONE")
                draw()
            yield (i + 1) / len(draws)
        with offscreen.bind():
            return read_pixels(gpu.state.active_framebuffer_get(), width, height)
    finally:
        offscreen.free()


def run_steps(steps, progress: Callable[[float], None] | None = None):
    """Run a stepped piece of work (a generator yielding the fraction done) to its end; its return value."""
    while True:
        try:
            fraction = next(steps)
        except StopIteration as done:
            return done.value
        if progress:
            progress(fraction)


def read_pixels(fb, width: int, height: int, slot: int = 0) -> np.ndarray:
    """Float RGBA of the framebuffer's colour attachment `slot`, (height, width, 4), bottom row first.

    Blender's Buffer exports its memory with reversed strides to the buffer protocol (seen in 5.0.1),
    so we view the C-ordered memory with the strides it really has instead of trusting them.
    """
    view = np.asarray(fb.read_color(0, 0, width, height, 4, slot, "FLOAT"))
    if view.dtype != np.float32 or view.size != width * height * 4:
        raise RuntimeError(f"unexpected framebuffer read-back {view.dtype} {view.shape}")
    if view.flags.c_contiguous and view.shape == (height, width, 4):
        return view.copy()
    strides = (width * 16, 16, 4)
    return np.lib.stride_tricks.as_strided(view, shape=(height, width, 4), strides=strides).copy()
