"""Distributed bakes on Dask (dask.distributed), an existing engine rather than a scheduler of our own:
`local:N` starts a LocalCluster of N worker processes on this machine, `tcp://HOST:PORT` joins a
running scheduler whose workers can import bpy and this extension (docs/bake.md). The engine retries
the tasks of workers that die; results come back to this process, which writes every file itself,
atomically, so no frame is ever half-written."""

from __future__ import annotations

import contextlib
import importlib
import os
import re
import sys
from collections.abc import Iterator
from dataclasses import dataclass

from .errors import NubisError

try:  # optional: only distributed bakes need it
    import distributed
except ImportError:  # pragma: no cover - exercised by the message test with the module hidden
    distributed = None

MAX_LOCAL_WORKERS = 64
RETRIES = 2  # a task whose worker died runs again, up to this many more times


@dataclass(frozen=True)
class SceneSource:
    """How a worker process finds the scene: a preset (name or .toml path) or a saved .blend."""

    preset: str | None = None
    blend: str | None = None


@dataclass(frozen=True)
class BakeOptions:
    voxel_size: float | None = None
    camera_only: bool = False
    size: tuple[int, int] | None = None
    half: bool = False
    velocity: bool = False


@dataclass(frozen=True)
class Engine:
    local_workers: int = 0  # local:N
    address: str = ""  # tcp://HOST:PORT

    def __str__(self) -> str:
        return f"local:{self.local_workers}" if self.local_workers else self.address


def parse_engine(text: str) -> Engine:
    m = re.fullmatch(r"local:(\d+)", text.strip())
    if m:
        n = int(m.group(1))
        if not 1 <= n <= MAX_LOCAL_WORKERS:
            raise NubisError(f"--distributed {text}: use between 1 and {MAX_LOCAL_WORKERS} local workers")
        return Engine(local_workers=n)
    m = re.fullmatch(r"(tcp|tls)://([A-Za-z0-9.\-\[\]:]+):(\d+)", text.strip())
    if m and 0 < int(m.group(3)) < 65536:
        return Engine(address=text.strip())
    raise NubisError(
        f"--distributed takes local:N (N worker processes here) or tcp://HOST:PORT (a Dask scheduler), not '{text}'"
    )


def require() -> None:
    if distributed is None:
        raise NubisError(
            "distributed bakes need Dask: install it into Blender's Python with "
            "'python -m pip install dask[distributed]==2026.8.0' (or bake without --distributed)"
        )


@contextlib.contextmanager
def client(engine: Engine) -> Iterator[object]:
    """A dask.distributed Client on the engine; a local cluster is closed with it."""
    require()
    if engine.local_workers:
        cluster = distributed.LocalCluster(
            n_workers=engine.local_workers,
            threads_per_worker=1,  # one GPU context per worker process
            processes=True,
            dashboard_address=None,
            memory_limit=0,
        )
        try:
            with distributed.Client(cluster) as c:
                yield c
        finally:
            cluster.close()
        return
    try:
        c = distributed.Client(engine.address, timeout=30)
    except (OSError, TimeoutError) as err:
        raise NubisError(
            f"cannot reach the Dask scheduler at {engine.address} ({err}): start it or check the address"
        ) from None
    with c:
        yield c


def run_task(function: str, *args):
    """A worker's entry point: call `function` ("module.name") with `args`. Tasks name their function
    rather than pickle a reference to it, because the worker must not import bpy through the paths
    the client inherited: a spawned worker starts with the client's sys.path, where the bpy wheel has
    put Blender's own `scripts/modules` (holding a `bpy` package that only works inside Blender) ahead
    of the wheel itself."""
    if "bpy" not in sys.modules:
        marker = f"{os.sep}bpy{os.sep}"
        sys.path[:] = [p for p in sys.path if marker not in p]
    module, name = function.rsplit(".", 1)
    return getattr(importlib.import_module(module), name)(*args)
