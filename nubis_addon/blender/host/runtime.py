"""Session-wide GPU resources, the noise they are made from, and the user's folders (cache, presets).

Noise for a new seed takes seconds to generate (pure numpy). Headless callers (renders, bakes, the
command line, tests) get it synchronously from :func:`cloud_gpu`. The 3D viewport's draw callback
must not wait: :func:`cloud_gpu_nowait` hands the generation (or the cache read) to a worker thread,
returns the set already on the GPU meanwhile, and asks for a redraw when the new one is ready. The
worker runs numpy only; GPU textures are made on Blender's main thread, in the draw.
"""

from __future__ import annotations

import contextlib
import os
import threading
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path

import bpy

from ...core import bricks, noise
from ...core.errors import NubisError
from ...render.engine import CloudGPU
from ...render.gpu_context import ensure_gpu_context, release_at_exit

# "bl_ext.<repo>.nubis" when installed, "nubis_addon"'s parent otherwise (this is <it>.nubis_addon.blender.host)
_EXT_PACKAGE = __package__.rsplit(".", 3)[0]
_gpu: dict[int, CloudGPU] = {}
release_at_exit(_gpu.clear)


def _user_folder(env: str, name: str) -> Path:
    """A folder of the user's: `env` overrides it; installed, the extension's user folder; run as a plain
    module (python -m nubis_addon), the folder the installed extension would use."""
    override = os.environ.get(env)
    if override:
        path = Path(override)
    elif _EXT_PACKAGE.startswith("bl_ext."):
        path = Path(bpy.utils.extension_path_user(_EXT_PACKAGE, path=name, create=True))
    else:
        path = Path(bpy.utils.user_resource("EXTENSIONS", path=os.path.join(".user", "user_default", "nubis", name)))
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise NubisError(
            f"cannot create the folder '{path}' ({err.strerror}): set {env} to a writable folder"
        ) from None
    return path


def vdb_gpu_budget() -> int:
    """Bytes the VDB clouds may take on the GPU: NUBIS_VDB_GPU_BUDGET (megabytes) for the command line, else
    the preference, or its default where the add-on's preferences are not registered (a script that
    imports the package without enabling it)."""
    override = os.environ.get("NUBIS_VDB_GPU_BUDGET", "").strip()
    if override:
        try:
            megabytes = int(override)
        except ValueError:
            megabytes = 0
        if not 1 <= megabytes <= 65536:
            raise NubisError(
                f"NUBIS_VDB_GPU_BUDGET is {override!r}: set it to a whole number of megabytes from 1 to 65536"
            )
        return megabytes * 2**20
    addon = bpy.context.preferences.addons.get(_EXT_PACKAGE)
    prefs = getattr(addon, "preferences", None)
    megabytes = getattr(prefs, "vdb_gpu_budget", None)
    return int(megabytes) * 2**20 if megabytes else bricks.DEFAULT_GPU_LIMIT


def cache_dir() -> Path:
    """Where generated noise volumes are cached: never inside the extension's own folder."""
    return _user_folder("NUBIS_CACHE_DIR", "cache")


def user_preset_dir() -> Path:
    """Where the user's own presets are saved (NUBIS_PRESET_DIR overrides it)."""
    return _user_folder("NUBIS_PRESET_DIR", "presets")


def _install(seed: int, noise_set: noise.NoiseSet) -> CloudGPU:
    _gpu.clear()  # one texture set at a time keeps GPU memory inside Guerrilla's 20 MB budget
    _gpu[seed] = CloudGPU(noise_set)
    return _gpu[seed]


def cloud_gpu(seed: int) -> CloudGPU:
    """The GPU inputs for a noise seed, generated or loaded from the cache once per session; waits for
    them (for a generation already running on the worker, it waits for that one)."""
    ensure_gpu_context()
    if seed not in _gpu:
        job = _jobs.pop(seed, None)
        _install(seed, _result(seed, job) if job is not None else noise.load_or_generate(cache_dir(), seed))
    return _gpu[seed]


def loaded_gpu(seed: int) -> CloudGPU | None:
    """The GPU inputs for a seed if this session has them, without making or waiting for any."""
    return _gpu.get(seed)


# ---- noise off the draw callback ---------------------------------------------------------------------

_executor: list[ThreadPoolExecutor] = []
_jobs: dict[int, Future] = {}  # seed -> its generation on the worker (at most one runs at a time)
_failed: dict[int, str] = {}  # seed -> why its generation failed (not retried until the seed changes)
_lock = threading.Lock()
_on_ready: list[Callable[[], None]] = []
_POLL_S = 0.1  # how often the main thread looks whether the worker has finished


def _worker() -> ThreadPoolExecutor:
    if not _executor:
        _executor.append(ThreadPoolExecutor(max_workers=1, thread_name_prefix="nubis-noise"))
    return _executor[0]


def _result(seed: int, job: Future) -> noise.NoiseSet:
    try:
        return job.result()
    except Exception as err:  # MemoryError, an OS error reading the cache, ...
        reason = str(err) or type(err).__name__
        _failed[seed] = f"the noise for seed {seed} could not be made ({reason}): free memory, then change the seed"
        raise NubisError(_failed[seed]) from None


def noise_generating() -> int | None:
    """The seed whose noise the worker is making, or None (for the sidebar's status line)."""
    with _lock:
        return next((seed for seed, job in _jobs.items() if not job.done()), None)


def cloud_gpu_nowait(seed: int, on_ready: Callable[[], None] | None = None) -> CloudGPU | None:
    """For the draw callback: the seed's GPU inputs if its noise is ready. Otherwise its noise is made on
    the worker thread (once the one running, if any, is done: a slider drag makes the first and the last
    seed, not every one in between), and this returns what is on the GPU now, the previous seed's set or
    None. `on_ready` is called on the main thread when the worker finishes (to redraw)."""
    if bpy.app.background:
        ensure_gpu_context()  # a draw callback in the interface has its window's context current
    if seed in _gpu:
        return _gpu[seed]
    for other in [s for s in _failed if s != seed]:
        del _failed[other]  # the seed changed: a failed one may be tried again later
    if seed in _failed:
        raise NubisError(_failed[seed])
    with _lock:
        finished = [(s, j) for s, j in _jobs.items() if j.done()]
    for done_seed, job in finished:
        del _jobs[done_seed]
        if done_seed == seed:
            return _install(seed, _result(seed, job))
        if job.exception() is None:
            _install(done_seed, job.result())  # a seed passed on the way shows while the wanted one is made
    if on_ready is not None:
        _on_ready[:] = [on_ready]
    with _lock:
        if not _jobs:  # one generation at a time: the seed wanted when it ends is the next one made
            _jobs[seed] = _worker().submit(noise.load_or_generate, cache_dir(), seed)
    if not bpy.app.timers.is_registered(_poll):
        bpy.app.timers.register(_poll, first_interval=_POLL_S)
    return next(iter(_gpu.values()), None)


def _poll():
    """Timer on the main thread: when the worker has finished, the views redraw (and their draw takes the
    set, or asks for the next seed)."""
    if noise_generating() is not None:
        return _POLL_S
    for callback in _on_ready:
        callback()
    return None


def wait_for_noise(timeout: float | None = None) -> None:
    """Block until the worker is idle (for tests and for unregistering)."""
    for job in list(_jobs.values()):
        job.exception(timeout)


def free() -> None:
    _gpu.clear()
    _failed.clear()
    if bpy.app.timers.is_registered(_poll):
        bpy.app.timers.unregister(_poll)
    for job in _jobs.values():
        job.cancel()
    _jobs.clear()
    if _executor:
        _executor.pop().shutdown(wait=False, cancel_futures=True)  # a running generation ends by itself


_own_renders = [0]


@contextlib.contextmanager
def own_render():
    """Around a render Nubis makes itself (the Cycles reference of the baked VDB, the benchmark's EEVEE
    frame): the F12 clouds (blender/f12/scene_render.py) stay out of it."""
    _own_renders[0] += 1
    try:
        yield
    finally:
        _own_renders[0] -= 1


def own_render_running() -> bool:
    return _own_renders[0] > 0
