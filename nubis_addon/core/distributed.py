"""Distributed bakes on Dask (dask.distributed), an existing engine rather than a scheduler of our own:
`local:N` starts a LocalCluster of N worker processes on this machine, `tcp://HOST:PORT` joins a
running scheduler whose workers can import bpy and this extension (docs/bake.md). The engine retries
the tasks of workers that die; results come back to this process, which writes every file itself,
atomically, so no frame is ever half-written.

Everything that can go wrong with the cluster ends in one sentence within a bounded time (30 s by
default, NUBIS_DASK_TIMEOUT seconds if set): an address that is not a Dask scheduler, a scheduler
without workers, workers that cannot import the extension, workers that keep dying, a full disk.
The scheduler itself needs nothing of ours: tasks carry only plain data and an entry point that is
sent by value, so a stock `dask scheduler` serves them."""

from __future__ import annotations

import asyncio
import concurrent.futures
import contextlib
import dataclasses
import errno
import os
import re
import socket
import struct
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

from . import interrupt
from .errors import NubisError
from .jobs import BakeOptions  # noqa: F401 - the options a farm task carries (plain() below)

# Dask's modules, optional (only distributed bakes need them) and imported by require() on first use: at
# the top they took 1.3 s of every command's start-up.
dask = distributed = None

MAX_LOCAL_WORKERS = 64
# A task that raises runs again, up to this many more times (one whose worker dies runs again up to the
# scheduler's own distributed.scheduler.allowed-failures).
RETRIES = 2
TIMEOUT_ENV = "NUBIS_DASK_TIMEOUT"
DEFAULT_TIMEOUT = 30.0  # seconds to connect, to see a first worker, to hear from a lost cluster again
POLL = 1.0  # seconds between checks that a running bake still has workers
GREETING_WAIT = 3.0  # seconds a scheduler may take to greet before the address is asked whether it is a web server
# The package this module belongs to ("nubis_addon"): what a worker must be able to import.
PACKAGE = __name__.rsplit(".", 2)[0]
# Dask's TCP messages start with their length (8 bytes, little-endian); a handshake is a few hundred
# bytes. Anything that starts otherwise is another protocol.
_GREETING_MAX = 1 << 20
# What a future raises once the client has lost the scheduler (Dask's own classes derive from these).
_CANCELLED = (asyncio.CancelledError, concurrent.futures.CancelledError)


@dataclass(frozen=True)
class SceneSource:
    """How a worker process finds the scene: a preset (name or .toml path) or a saved .blend."""

    preset: str | None = None
    blend: str | None = None


def plain(value) -> dict:
    """A SceneSource or BakeOptions as a dict of built-in values, the form tasks carry: the scheduler
    unpickles the task graph and must not need this extension to do it."""
    return dataclasses.asdict(value)


@dataclass(frozen=True)
class Engine:
    local_workers: int = 0  # local:N
    address: str = ""  # tcp://HOST:PORT

    def __str__(self) -> str:
        return f"local:{self.local_workers}" if self.local_workers else self.address


def parse_engine(text: str) -> Engine:
    timeout()  # a bad NUBIS_DASK_TIMEOUT is said before any work
    m = re.fullmatch(r"local:(\d+)", text.strip())
    if m:
        n = int(m.group(1))
        if not 1 <= n <= MAX_LOCAL_WORKERS:
            raise NubisError(f"--distributed {text}: use between 1 and {MAX_LOCAL_WORKERS} local workers")
        return Engine(local_workers=n)
    m = re.fullmatch(r"(tcp|tls)://([A-Za-z0-9.\-\[\]:]+):(\d+)", text.strip())
    if m and m.group(1) == "tls":
        # Dask's TLS needs a certificate, a key and a CA, which the command line has no way to pass.
        raise NubisError(
            f"--distributed {text}: tls:// is not supported (Dask needs certificates the command line cannot "
            "pass): use tcp://HOST:PORT on a trusted network, or an SSH tunnel to the scheduler"
        )
    if m and 0 < int(m.group(3)) < 65536:
        return Engine(address=text.strip())
    raise NubisError(
        f"--distributed takes local:N (N worker processes here) or tcp://HOST:PORT (a Dask scheduler), not '{text}'"
    )


def timeout() -> float:
    """Seconds to wait for the cluster at each step: NUBIS_DASK_TIMEOUT, else 30."""
    text = os.environ.get(TIMEOUT_ENV, "").strip()
    if not text:
        return DEFAULT_TIMEOUT
    try:
        seconds = float(text)
    except ValueError:
        seconds = -1.0
    if not 0 < seconds <= 3600:
        raise NubisError(f"{TIMEOUT_ENV}={text!r}: give the seconds to wait for the Dask cluster, e.g. 30")
    return seconds


def require() -> None:
    """Dask imported, or a message that says how to install it."""
    global dask, distributed
    if distributed is not None:
        return
    try:
        import dask as dask_module
        import distributed as distributed_module
    except ImportError:
        raise NubisError(
            "distributed bakes need Dask: install it into Blender's Python with "
            "'python -m pip install dask[distributed]==2026.8.0' (or bake without --distributed)"
        ) from None
    dask, distributed = dask_module, distributed_module


def _extension_root() -> str:
    """The folder holding the package here: what PYTHONPATH names for a worker on a shared file system."""
    return str(Path(__file__).resolve().parents[2])


def worker_command(address: str) -> str:
    return (
        f"PYTHONPATH={_extension_root()} python -m distributed.cli.dask_worker {address} --nthreads 1 "
        "(with the bpy wheel installed; docs/bake.md)"
    )


@contextlib.contextmanager
def client(engine: Engine) -> Iterator[object]:
    """A dask.distributed Client on the engine, with at least one worker that can import the extension;
    a local cluster is closed with it, and its files (Dask's scratch space, each worker's Blender
    session folder) go with a private folder."""
    require()
    seconds = timeout()
    if engine.local_workers:
        # Every Dask server (the scheduler here too, not only the workers) makes its scratch space in
        # Dask's temporary-directory, by default the system's temporary folder.
        with interrupt.temporary_dir("nubis-dask-") as tmp, dask.config.set({"temporary-directory": tmp}):
            try:
                cluster = distributed.LocalCluster(
                    n_workers=engine.local_workers,
                    threads_per_worker=1,  # one GPU context per worker process
                    processes=True,
                    dashboard_address=None,
                    memory_limit=0,
                    local_directory=tmp,
                    # Blender makes its session folder under TMPDIR and, without its teardown, leaves it.
                    env={"TMPDIR": tmp},
                )
            except OSError as err:
                raise NubisError(
                    f"cannot start {engine.local_workers} local Dask workers ({_reason(err)}): "
                    "check the free space in the temporary folder"
                ) from None
            try:
                with distributed.Client(cluster) as c:
                    _check_workers(c, engine, seconds)
                    yield c
            finally:
                cluster.close()
        return
    check_scheduler(engine.address, seconds)
    try:
        c = distributed.Client(engine.address, timeout=seconds)
    except Exception as err:  # whatever stops the connection, it is about the address or the network
        if re.search(r"\b(Worker|Nanny|Server)\.identity\(", str(err)):  # a worker answers, not a scheduler
            raise NubisError(
                f"{engine.address} is a Dask worker's port, not the scheduler's: give the scheduler's address "
                "(its log names it after 'Scheduler at:')"
            ) from None
        raise NubisError(
            f"cannot connect to the Dask scheduler at {engine.address} ({_reason(err)}): "
            "check that 'dask scheduler' runs there and the address"
        ) from None
    with c:
        _check_workers(c, engine, seconds)
        yield c


def _reason(err: BaseException) -> str:
    text = " ".join(str(err).split()) or type(err).__name__
    return text if len(text) <= 200 else text[:200] + "..."


def check_scheduler(address: str, seconds: float) -> None:
    """Refuse, in one sentence, an address where no Dask scheduler listens. Dask's own client waits
    forever on a server that never answers its handshake (an HTTP server, a silent listener) and reads
    another protocol's greeting as a message length (an SSH banner: an attempt to allocate exabytes).
    A scheduler sends its handshake as soon as it accepts a connection, so the first bytes tell."""
    host, port = address.split("://", 1)[1].rsplit(":", 1)
    host = host.strip("[]")
    try:
        sock = socket.create_connection((host, int(port)), timeout=seconds)
    except socket.gaierror as err:
        raise NubisError(
            f"cannot find the host of the Dask scheduler {address} ({err.strerror}): check the name"
        ) from None
    except TimeoutError:
        raise NubisError(
            f"no answer from the Dask scheduler at {address} in {seconds:g} s: check the address and the firewall"
        ) from None
    except OSError as err:
        raise NubisError(
            f"cannot reach the Dask scheduler at {address} ({err.strerror or _reason(err)}): "
            "start it ('dask scheduler') or check the address"
        ) from None
    with sock:
        begun = time.monotonic()
        head = _receive(sock, 8, begun + min(seconds / 2, GREETING_WAIT))
        if not head:
            # A server that waits for the client to speak first may be a web server (the dashboard's port):
            # ask as a browser would. A scheduler that is merely busy still sends its handshake meanwhile.
            with contextlib.suppress(OSError):
                sock.sendall(b"GET / HTTP/1.0\r\n\r\n")
            head = _receive(sock, 8, begun + seconds)
        if len(head) == 8 and 16 <= struct.unpack("<Q", head)[0] <= _GREETING_MAX:
            return
        if not head:
            why = f"it accepted the connection but said nothing in {seconds:g} s"
        else:
            head += _receive(sock, 120, time.monotonic() + 0.5, whole=False)
            said = head.decode("latin-1").strip().splitlines()[0][:60] if head.strip() else repr(head[:16])
            if said.startswith("HTTP/"):
                why = "an HTTP server: the dashboard is not the scheduler port"
            else:
                why = f"it said '{said}'"
        raise NubisError(
            f"{address} does not speak Dask's protocol ({why}): give the scheduler's own port (8786 unless set; "
            "its log names it after 'Scheduler at:')"
        )


def _receive(sock: socket.socket, n: int, deadline: float, whole: bool = True) -> bytes:
    """Up to `n` bytes before `deadline` or the end of the stream; with `whole` False, what comes first."""
    data = b""
    while len(data) < n:
        left = deadline - time.monotonic()
        if left <= 0:
            break
        sock.settimeout(left)
        try:
            chunk = sock.recv(n - len(data))
        except (TimeoutError, OSError):
            break
        if not chunk:
            break
        data += chunk
        if not whole:
            break
    return data


def _check_workers(c, engine: Engine, seconds: float) -> None:
    """Wait (boundedly) for a first worker, then ask every worker whether it can import bpy and the
    extension: a worker that cannot would fail every task it is given."""
    try:
        c.wait_for_workers(1, timeout=seconds)
    except TimeoutError:  # before OSError, its base class
        raise NubisError(
            f"the Dask scheduler at {engine} has no workers after {seconds:g} s: start workers with "
            f"{worker_command(str(engine))}"
        ) from None
    except OSError as err:
        raise _lost(engine, err) from None
    try:
        missing = c.run(_missing_modules, PACKAGE, on_error="return")
    except Exception as err:  # the broadcast itself failed: the cluster went away meanwhile
        raise NubisError(f"cannot reach the Dask workers at {engine} ({_reason(err)}): check the cluster") from None
    for worker, names in sorted(missing.items()):
        if isinstance(names, BaseException):
            raise NubisError(f"the Dask worker {worker} at {engine} does not answer ({_reason(names)})")
        if names:
            raise cannot_import(engine, ", ".join(names), worker)


def cannot_import(engine: Engine | str, names: str, worker: str = "") -> NubisError:
    on = f" on {worker}" if worker else ""
    if PACKAGE in names:
        return NubisError(
            f"the workers at {engine} cannot import the extension (No module named '{PACKAGE}'{on}): start them "
            f"with {worker_command(str(engine))}"
        )
    return NubisError(
        f"the workers at {engine} cannot import {names}{on}: install the bpy wheel (Blender as a Python "
        "module) into the workers' Python (docs/bake.md)"
    )


def describe(err: BaseException, engine: Engine, what: str) -> BaseException:
    """The user's sentence for a task that failed `what` ("frame 3"), or `err` itself for a fault of ours."""
    if isinstance(err, NubisError):
        return err
    if isinstance(err, distributed.KilledWorker):
        deaths = err.allowed_failures + 1
        times = "once" if deaths == 1 else f"{deaths} times"
        return NubisError(
            f"a worker died {times} running {what} (out of memory? a crash in Blender?): see the workers' "
            "logs, then bake with fewer workers or a larger --voxel-size"
        )
    if isinstance(err, ModuleNotFoundError):
        m = re.search(r"No module named '([^']+)'", str(err))
        name = (err.name or (m.group(1) if m else "")).split(".")[0]
        if name in (PACKAGE.split(".")[0], "bpy"):
            return cannot_import(engine, PACKAGE if name != "bpy" else "bpy")
    if isinstance(err, OSError) and err.errno == errno.ENOSPC:
        return NubisError(f"a worker's disk is full running {what} ({err.strerror}): free some space there")
    if isinstance(err, _CANCELLED):
        return _lost(engine, err)
    return err


def completed(c, futures: list, engine: Engine, names: dict) -> Iterator[tuple[object, object]]:
    """Each future with its result, as they finish. A task that failed ends the bake with the user's
    sentence for it (`names` maps a future's key to what it bakes); a cluster left without workers for
    the timeout, or a scheduler that went away, ends it too, rather than waiting for what may never come."""
    seconds = timeout()
    pending = list(futures)
    alone_since = None
    while pending:
        try:
            done, rest = distributed.wait(pending, timeout=POLL, return_when="FIRST_COMPLETED")
        except TimeoutError:
            try:
                workers = c.nthreads()
            except Exception as err:  # the scheduler is gone: the client's calls fail as the connection does
                raise _lost(engine, err) from None
            if workers:
                alone_since = None
            elif alone_since is None:
                alone_since = time.monotonic()
            elif time.monotonic() - alone_since > seconds:
                raise NubisError(
                    f"the Dask scheduler at {engine} has had no workers for {seconds:g} s: start workers "
                    f"with {worker_command(str(engine))}"
                ) from None
            continue
        except _CANCELLED as err:  # the client lost the scheduler and cancelled every future
            raise _lost(engine, err) from None
        pending = list(rest)
        for fut in done:
            try:
                value = fut.result()
            except (Exception, *_CANCELLED) as err:
                user = describe(err, engine, names.get(fut.key, "a task"))
                if user is err:
                    raise
                raise user from None
            yield fut, value


def _lost(engine: Engine, err: BaseException) -> NubisError:
    return NubisError(
        f"lost the connection to the Dask scheduler at {engine} ({type(err).__name__}): check that it still "
        "runs, then bake again"
    )


def _worker_entry_points():
    """The functions a worker runs, defined here so that they travel by value (cloudpickle sends a nested
    function's code, a module-level one only its name): the scheduler unpickles the task graph, and
    neither it nor a worker without the extension must need to import this module to do so."""

    def run_task(function, *args):
        """Call `function` ("module.name") with `args`. Tasks name their function rather than pickle a
        reference to it, because the worker must not import bpy through the paths the client inherited:
        a spawned worker starts with the client's sys.path, where the bpy wheel has put Blender's own
        `scripts/modules` (holding a `bpy` package that only works inside Blender) ahead of the wheel."""
        import importlib
        import os
        import sys

        if "bpy" not in sys.modules:
            marker = f"{os.sep}bpy{os.sep}"
            sys.path[:] = [p for p in sys.path if marker not in p]
        module, name = function.rsplit(".", 1)
        return getattr(importlib.import_module(module), name)(*args)

    def missing_modules(package):
        """The modules a bake needs that this worker cannot find (without importing them: this runs on
        the worker's event loop, and bpy belongs to the task thread)."""
        import importlib.util

        return [name for name in ("bpy", package) if importlib.util.find_spec(name) is None]

    return run_task, missing_modules


run_task, _missing_modules = _worker_entry_points()
