"""Bakes of frame sequences and bakes spread over Dask workers (docs/bake.md).

A sequence writes one file per frame, named with Blender's `#` padding (`clouds_####.vdb`), all of
them committed together at the end (core/staging.py). With an engine (core/distributed.py), the frames
of a sequence, or the tiles of a single frame, run as Dask tasks in worker processes that load the
same scene themselves (a preset by name or a saved .blend) and bake with the same GPU code; the
files come back to this process, which writes them atomically. Tiles carry absolute voxel indices,
so the merged grids equal the serial bake's voxel for voxel."""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import bpy

from ...core import bundled, distributed, interrupt, sequence, vdbwrite
from ...core.distributed import SceneSource
from ...core.errors import NubisError
from ...core.fsutil import check_output_path, shown, sync_to_disk
from ...core.jobs import BakeOptions
from ...core.staging import FolderGone, output_set
from . import pipeline, snapshot

Progress = Callable[[float], None]
# The tasks' entry points, named (not imported): the worker side registers the extension, so it sits above
# everything it registers (blender/headless/daskworker.py).
_WORKER = __package__.rpartition(".")[0] + ".headless.daskworker"
_TASK_FRAME = f"{_WORKER}.worker_bake_frame"
_TASK_TILES = f"{_WORKER}.worker_bake_tiles"


@dataclass
class SequenceResult:
    results: list = field(default_factory=list)  # pipeline.BakeResult per frame
    seconds: float = 0.0
    engine: str = ""


def source_of(scene, preset: str | None, blend: str | None) -> SceneSource:
    """The source a worker can load: the command line's --preset or --blend, else the saved file."""
    if blend:
        return SceneSource(blend=str(Path(blend).expanduser().resolve()))
    if preset:
        path = Path(preset).expanduser()
        return SceneSource(preset=str(path.resolve()) if path.suffix == ".toml" else preset)
    if bpy.data.filepath and not bpy.data.is_dirty:
        return SceneSource(blend=bpy.data.filepath)
    if bpy.data.filepath:
        raise NubisError("distributed workers read the saved .blend: save the file first, then bake")
    return SceneSource(preset=scene.nubis.preset or "default")


def bake_sequence(
    scene,
    out: str | os.PathLike,
    frames: list[int],
    options: BakeOptions,
    engine: distributed.Engine | None = None,
    source: SceneSource | None = None,
    progress: Progress | None = None,
) -> SequenceResult:
    """Bake `frames` to the files `out` names (with `#` padding), serially or on `engine`; the files
    replace earlier ones together or not at all."""
    start = time.perf_counter()
    paths = [check_output_path(p, (".vdb",)) for p in sequence.sequence_paths(out, frames)]
    result = SequenceResult(engine=str(engine or ""))
    try:
        with output_set() as outputs:
            staged = [outputs.stage(p) for p in paths]
            try:
                if engine is None:
                    result.results = _bake_serial(scene, outputs, frames, staged, options, progress)
                else:
                    result.results = _bake_on(engine, scene, source, frames, options, staged, progress)
            except (OSError, NubisError):
                outputs.check()  # a write that failed because the folder went is said as that
                raise
    except FolderGone as gone:  # the folder went while the frames were baked (core/staging.py)
        raise gone.said(*pipeline.BAKE_GONE) from None
    for r, path in zip(result.results, paths, strict=True):
        r.path = path
    result.seconds = time.perf_counter() - start
    return result


def _bake_serial(scene, outputs, frames, staged, options: BakeOptions, progress) -> list:
    """The frames one after the other in this process, each to its staged path."""
    results = []
    for n, (frame, path) in enumerate(zip(frames, staged, strict=True)):
        outputs.check()  # a folder gone since the last frame is not made again for the next
        scene.frame_set(frame)
        results.append(pipeline.bake(scene, path, options, _sub_progress(progress, n, len(frames))))
    return results


def _bake_on(engine, scene, source, frames, options: BakeOptions, staged, progress) -> list:
    """The frames as Dask tasks (or one frame's tiles), each file written here to its staged path."""
    if source is None:
        raise NubisError("a distributed bake needs the scene's source (a preset or a saved .blend)")
    with distributed.client(engine) as client:
        if len(frames) == 1:
            scene.frame_set(frames[0])
            return [_bake_tiles_distributed(client, engine, scene, source, frames[0], options, staged[0], progress)]
        finals = [shown(path) for path in staged]  # where each file goes, for messages and the results
        return _bake_frames_distributed(client, engine, source, frames, options, staged, finals, progress)


def _sub_progress(progress: Progress | None, n: int, total: int) -> Progress | None:
    if progress is None:
        return None
    return lambda f: progress((n + f) / total)


def _bake_frames_distributed(client, engine, source, frames, options, staged, paths, progress):
    futures = [
        client.submit(
            distributed.run_task,
            _TASK_FRAME,
            distributed.plain(source),
            int(f),
            distributed.plain(options),
            pure=False,
            retries=distributed.RETRIES,
        )
        for f in frames
    ]
    index = {fut.key: n for n, fut in enumerate(futures)}
    names = {fut.key: f"frame {frames[n]}" for n, fut in enumerate(futures)}
    results = [None] * len(frames)
    done = 0
    for fut, out in distributed.completed(client, futures, engine, names):
        n = index[fut.key]
        _write(staged[n], paths[n], out["data"])
        results[n] = pipeline.BakeResult(
            paths[n], out["plan"], out["active"], out["seconds"], tuple(out["grids"]), frames[n]
        )
        done += 1
        if progress:
            progress(done / len(frames))
    return results


def _write(path: Path, final: Path, data: bytes) -> None:
    """A worker's file written here, and on the disk before it may replace `final` (a full disk says so)."""
    try:
        path.write_bytes(data)
    except OSError as err:
        raise NubisError(f"writing '{final}' failed ({err.strerror}): check the free disk space") from None
    sync_to_disk(path, final)


def _bake_tiles_distributed(client, engine, scene, source, frame, options, staged, progress):
    start = time.perf_counter()
    snap = snapshot.take(scene, options)
    plan = snap.plan
    busy = [n for n, t in enumerate(plan.tiles) if t.spans]
    workers = max(1, sum(client.nthreads().values()))
    # A few tasks per worker evens out the load and keeps a retried task short.
    groups = _balanced(busy, [plan.tiles[n].voxels for n in busy], 4 * workers)
    futures = [
        client.submit(
            distributed.run_task,
            _TASK_TILES,
            distributed.plain(source),
            int(frame),
            distributed.plain(options),
            [int(i) for i in ids],
            tuple(int(d) for d in plan.dims),
            pure=False,
            retries=distributed.RETRIES,
        )
        for ids in groups
    ]
    vdb = bundled.openvdb()
    merged = vdbwrite.SparseGrids(plan.voxel_size, plan.origin)
    merged.grid("density")
    done = 0
    ids_of = {fut.key: ids for fut, ids in zip(futures, groups, strict=True)}
    what = {key: f"tiles {_spans(ids)} of frame {frame}" for key, ids in ids_of.items()}
    with interrupt.temporary_dir("nubis-merge-") as tmp:
        for n, (fut, data) in enumerate(distributed.completed(client, futures, engine, what)):
            part = Path(tmp) / f"part{n}.vdb"
            try:
                part.write_bytes(data)
            except OSError as err:
                raise NubisError(
                    f"writing a part of the bake to the temporary folder '{tmp}' failed ({err.strerror}): "
                    "check the free disk space there (TMPDIR)"
                ) from None
            grids, _meta = vdb.readAll(str(part))
            part.unlink()
            for g in grids:
                # Tiles never overlap: each part's voxels are copied in, tile by tile, unchanged.
                for t in (plan.tiles[i] for i in ids_of[fut.key]):
                    for k0, k1 in t.spans:
                        merged.add_region(g, (t.i0, t.j0, k0), (t.nx, t.ny, k1 - k0))
            done += 1
            if progress:
                progress(done / len(futures))
    names = tuple(
        n for n in ("density", "glow", "absorption", "velocity") if n == "density" or merged.active_voxels(n) > 0
    )
    merged.write(staged, snap.metadata(names), half=options.half)
    return pipeline.BakeResult(staged, plan, merged.active_voxels("density"), time.perf_counter() - start, names, frame)


def _spans(ids: list[int]) -> str:
    """Tile numbers for a message: "3-5, 9"."""
    runs: list[list[int]] = []
    for i in ids:
        if runs and i == runs[-1][1] + 1:
            runs[-1][1] = i
        else:
            runs.append([i, i])
    return ", ".join(str(a) if a == b else f"{a}-{b}" for a, b in runs)


def _balanced(items: list[int], weights: list[int], groups: int) -> list[list[int]]:
    """Split `items` into at most `groups` lists of similar total weight (largest first, to the lightest)."""
    groups = max(1, min(groups, len(items)))
    bins: list[list[int]] = [[] for _ in range(groups)]
    load = [0] * groups
    for w, item in sorted(zip(weights, items, strict=True), reverse=True):
        k = load.index(min(load))
        bins[k].append(item)
        load[k] += w
    return [sorted(b) for b in bins if b]
