"""A hostile round: probes the extension with damaged and absurd input and counts how each one ends.

Four classes of probes, each probe in a child process of its own under an 8 GB address-space cap
(RLIMIT_AS) with a timeout (60 s; 300 s for the probes that render), run one after the other:

- vdb:     `--vdb` files through `render`, `benchmark` and `compare --draft` (a small cumulus cut, filled with
           garbage, changed in place, files that are not files, grids Blender cannot draw, far voxels, huge
           tiles, huge values, too many files) and VDB clouds in saved .blend files (`render --blend`);
- paint:   `bpy.ops.nubis.paint_field` with scripted strokes in a child bpy process (far and non-finite
           points, absurd radii, strengths and pressures, empty and huge strokes, every channel and mode);
- presets: `render --preset FILE.toml` with a paint layer whose `dabs` rows break the rules;
- bake:    a headless `bake` whose output folder is removed, replaced, made read-only or renamed while it
           runs, or that is sent SIGINT, SIGTERM or SIGHUP.

Each probe ends as one of
- sentence: refused with exactly one `nubis: error:` line (for an in-process probe: one operator ERROR
  report), a single line under 1,000 characters, no "Traceback" or "internal error" in stderr, no stderr
  line over 1,000 characters, within 20 s;
- works:    exit 0 and the one thing the probe checks holds (the image exists, the stroke painted only over
  the field, the EXR is finite, ...);
- defect:   anything else (a signal, a traceback, an internal error, a multi-line or long message, a refusal
  that took over 20 s, the memory cap, a refusal where the probe should work, a file left half-written).

Run from the repository root (188 probes, about 12 minutes on a shared 2-core machine):

    .venv-5.3/bin/python tests/benchmarks/hostile_round.py

Options: `--only vdb,paint,presets,bake` runs some classes, `--match TEXT` only probes whose name holds
TEXT, `--list` lists the probes, `--repo DIR` probes another checkout of the extension (e.g. an export
of a commit) with this script, `--keep` keeps the scratch folder. Only the standard library, numpy and the
project's own modules are used; the parent process never imports bpy.
"""

from __future__ import annotations

import argparse
import json
import os
import random
import re
import resource
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

HERE = Path(__file__).resolve()
ROOT = HERE.parents[2]

MEMORY_CAP = 8 << 30
TIMEOUT = 60.0
TIMEOUT_RENDER = 300.0
REFUSAL_S = 20.0
SLOW_S = 5.0  # refusals slower than this are listed after the defects
LINE_MAX = 1000
SIZE = ["--width", "32", "--height", "18"]
CLASSES = ("vdb", "paint", "presets", "bake")
RESULT_TAG = "HR-RESULT "


# ---- the child processes ------------------------------------------------------------------------------------


def _cap_memory() -> None:
    resource.setrlimit(resource.RLIMIT_AS, (MEMORY_CAP, MEMORY_CAP))


def child_env() -> dict[str, str]:
    env = dict(os.environ)
    for name in ("NUBIS_DEBUG", "NUBIS_VERBOSE"):  # tracebacks and chatter on stderr would be counted
        env.pop(name, None)
    env["PYTHONUNBUFFERED"] = "1"
    return env


@dataclass
class Run:
    rc: int | None
    out: str
    err: str
    secs: float
    timed_out: bool
    notes: list[str] = field(default_factory=list)
    wall: float = 0.0  # the child's whole run (secs is the operator's own time for an in-process probe)


class Child:
    """A child process under the memory cap, in a session of its own (so a timeout kills all it started),
    its output in files (no pipe to fill)."""

    def __init__(self, argv: list[str], cwd: Path, scratch: Path):
        scratch.mkdir(parents=True, exist_ok=True)
        fd_out, self.out_path = tempfile.mkstemp(prefix="stdout-", dir=scratch)
        fd_err, self.err_path = tempfile.mkstemp(prefix="stderr-", dir=scratch)
        self.start = time.monotonic()
        self.proc = subprocess.Popen(
            argv,
            cwd=cwd,
            env=child_env(),
            stdin=subprocess.DEVNULL,
            stdout=fd_out,
            stderr=fd_err,
            preexec_fn=_cap_memory,
            start_new_session=True,
        )
        os.close(fd_out)
        os.close(fd_err)

    def elapsed(self) -> float:
        return time.monotonic() - self.start

    def stderr_now(self) -> str:
        return Path(self.err_path).read_text(errors="replace")

    def finish(self, timeout: float) -> Run:
        timed_out = False
        try:
            self.proc.wait(timeout=max(timeout - self.elapsed(), 0.1))
        except subprocess.TimeoutExpired:
            timed_out = True
            try:
                os.killpg(self.proc.pid, signal.SIGKILL)  # the child's own session: it and what it started
            except ProcessLookupError:
                pass
            self.proc.wait()
        secs = self.elapsed()
        out = Path(self.out_path).read_text(errors="replace")
        err = Path(self.err_path).read_text(errors="replace")
        os.unlink(self.out_path)
        os.unlink(self.err_path)
        return Run(self.proc.returncode, out, err, secs, timed_out, wall=secs)


def run_child(argv: list[str], cwd: Path, scratch: Path, timeout: float) -> Run:
    return Child(argv, cwd, scratch).finish(timeout)


# ---- probes and their classification ------------------------------------------------------------------------


@dataclass
class Probe:
    cls: str
    name: str
    expect: str  # "refuse", "work" or "either"
    run: Callable[[], Run]
    check: Callable[[Run], str | None] | None = None  # after exit 0: None when it did what it should
    after: Callable[[Run, bool], str | None] | None = None  # after any end (refused?): a defect or None
    interrupted_ok: tuple[int, ...] = ()  # exit codes of a signal probe that end with "nubis: interrupted"
    describe: str = ""


@dataclass
class Outcome:
    probe: Probe
    kind: str  # sentence / works / defect
    reason: str
    message: str
    secs: float
    run: Run


MEMORY_WORDS = ("MemoryError", "bad_alloc", "Malloc returns null", "Cannot allocate memory", "out of memory")


def classify(p: Probe, r: Run) -> Outcome:
    def end(kind: str, reason: str = "", message: str = "") -> Outcome:
        return Outcome(p, kind, reason, message, r.secs, r)

    err_lines = r.err.splitlines()
    refusal_lines = [x for x in err_lines if x.startswith("nubis: error:")]
    if p.interrupted_ok:
        refusal_lines += [x for x in err_lines if x.strip() == "nubis: interrupted"]
    message = refusal_lines[0] if refusal_lines else ""
    if r.timed_out:
        return end("defect", f"timed out after {r.secs:.0f} s and was killed", message)
    if r.rc is not None and r.rc < 0:
        try:
            name = signal.Signals(-r.rc).name
        except ValueError:
            name = str(-r.rc)
        cap = " (the memory cap?)" if any(w in r.err for w in MEMORY_WORDS) else ""
        return end("defect", f"killed by {name}{cap}", message)
    if "Traceback" in r.err:
        return end("defect", "a traceback on stderr", message)
    if "internal error" in r.err:
        return end("defect", "an internal error", message)
    long = [x for x in err_lines if len(x) > LINE_MAX]
    if long:
        return end("defect", f"a stderr line of {len(long[0])} characters", message)
    memory = [w for w in MEMORY_WORDS if w in r.err and not any(w in x for x in refusal_lines)]
    if memory:
        return end("defect", f"'{memory[0]}' on stderr (the memory cap?)", message)
    extra = p.after(r, r.rc != 0) if p.after else None
    if r.rc == 0:
        if p.expect == "refuse":
            return end("defect", "exit 0 where a refusal was expected", message)
        why = p.check(r) if p.check else None
        if extra:
            return end("defect", extra, message)
        if why:
            return end("defect", f"exit 0 but {why}", message)
        return end("works", "", r.out.strip().splitlines()[-1] if r.out.strip() else "")
    expected_rc = (1, *p.interrupted_ok)
    if r.rc not in expected_rc:
        return end("defect", f"exit code {r.rc}", message)
    if len(refusal_lines) != 1:
        return end("defect", f"exit {r.rc} with {len(refusal_lines)} 'nubis: error:' lines", message)
    if len(message) >= LINE_MAX:
        return end("defect", f"a message of {len(message)} characters", message)
    if r.secs > REFUSAL_S:
        return end("defect", f"the refusal took {r.secs:.1f} s (over {REFUSAL_S:g} s)", message)
    if p.expect == "work":
        return end("defect", "refused where it should work", message)
    if extra:
        return end("defect", extra, message)
    return end("sentence", "", message)


# ---- checks -------------------------------------------------------------------------------------------------


def is_png(path: Path) -> str | None:
    if not path.is_file():
        return f"'{path.name}' was not written"
    with open(path, "rb") as f:
        if f.read(8) != b"\x89PNG\r\n\x1a\n":
            return f"'{path.name}' is not a PNG"
    return None


def exists(path: Path) -> Callable[[Run], str | None]:
    def check(_r: Run) -> str | None:
        return None if path.is_file() and path.stat().st_size > 0 else f"'{path.name}' was not written"

    return check


def png_at(path: Path) -> Callable[[Run], str | None]:
    return lambda _r: is_png(path)


def nothing_left(out: Path) -> Callable[[Run, bool], str | None]:
    """After a refusal: no file under the output's name (a file, or a folder with files in it)."""

    def after(_r: Run, refused: bool) -> str | None:
        if not refused:
            return None
        if out.is_file():
            return f"refused but left '{out.name}'"
        if out.is_dir():
            files = [p for p in out.rglob("*") if p.is_file()]
            if files:
                return f"refused but left {len(files)} file(s) in '{out.name}', e.g. '{files[0].name}'"
        return None

    return after


# ---- helpers run in child bpy processes (`--helper ...`) ------------------------------------------------------


def _helper_path(repo: Path) -> None:
    sys.path[:0] = [str(repo), str(repo / "tests")]


def helper_make_vdbs(repo: Path, d: Path) -> None:
    """The VDB files of the vdb class, written with Blender's own OpenVDB (tests/vdb_helpers.py)."""
    _helper_path(repo)
    import numpy as np
    from vdb_helpers import DEFAULT_VIEW_BASE, _openvdb, bad_vdb, ball, write_cumulus, write_grid, write_two_voxels

    vdb = _openvdb()
    d.mkdir(parents=True, exist_ok=True)
    good = write_cumulus(d / "good.vdb", n_xy=14, n_z=14)
    data = good.read_bytes()
    n = len(data)
    for k in range(1, 6):
        (d / f"good_{k}.vdb").write_bytes(data)
    for cut in cut_points(n) + [2000]:
        (d / f"cut_{cut}.vdb").write_bytes(data[:cut])
    for seed in range(GARBAGE_SEEDS):
        rng = random.Random(seed)
        tail = bytes(rng.randrange(256) for _ in range(rng.randrange(10, 9000)))
        (d / f"garbage_{seed}.vdb").write_bytes(data[:64] + tail)
    for seed in range(FLIP_SEEDS):
        rng = random.Random(1000 + seed)
        b = bytearray(data)
        span = 600 if seed % 2 else n  # half of them in the header and metadata
        for _ in range(rng.randrange(1, 5)):
            at = rng.randrange(0, span)
            b[at] = (b[at] + rng.randrange(1, 256)) % 256  # a byte that differs
        (d / f"flip_{seed}.vdb").write_bytes(bytes(b))
    (d / "empty.vdb").write_bytes(b"")
    (d / "text.vdb").write_text("this is a text file, not a VDB\n")
    (d / "folder.vdb").mkdir(exist_ok=True)
    write_grid(d / "nameless.vdb", ball(), name="")
    bad = d / "bad"
    bad.mkdir(exist_ok=True)
    for kind in ("no float grid", "empty", "negative", "nan", "non-uniform", "sheared"):
        bad_vdb(bad, kind)
    g = vdb.FloatGrid()
    g.copyFromArray(np.ascontiguousarray(ball().transpose(2, 1, 0)), tolerance=0.0)
    g.name = "density"
    g.transform = vdb.createFrustumTransform(xyzMin=(0, 0, 0), xyzMax=(40, 40, 40), taper=0.5, depth=2000.0)
    vdb.write(str(d / "frustum.vdb"), grids=[g])
    for name, far in (("far_60000", (60_000, 0, 0)), ("far_16000", (16_000, 16_000, 0))):
        write_two_voxels(d / f"{name}.vdb", far)
    g = vdb.FloatGrid()
    g.name = "density"
    g.fill((0, 0, 0), (4095, 4095, 4095), 0.01, True)
    g.transform = vdb.createLinearTransform(voxelSize=1.0)
    vdb.write(str(d / "tiles_4096.vdb"), grids=[g])
    bx, by, bz = DEFAULT_VIEW_BASE
    rows = [[50, 0, 0, 0], [0, 50, 0, 0], [0, 0, 50, 0], [bx - 1000, by - 1000, bz, 1]]
    write_grid(d / "hot_1e7.vdb", ball() * (1e7 / 0.02), rows)
    print(json.dumps({"size": n}))


def helper_make_blends(repo: Path, d: Path, vdbs: Path) -> None:
    """Saved .blend files holding marked Volumes (docs/vdb.md#damaged-files)."""
    _helper_path(repo)
    import bpy

    import nubis_addon
    from nubis_addon.blender import ensure_registered
    from nubis_addon.blender.scene import scenepresets
    from nubis_addon.core.presets import load_preset

    nubis_addon.register()
    for name, vols in blend_specs(vdbs).items():
        bpy.ops.wm.read_factory_settings(use_empty=True)
        ensure_registered()
        scene = bpy.context.scene
        scenepresets.apply_preset(scene, load_preset("default"))
        for vname, path, scale in vols:
            vol = bpy.data.volumes.new(vname)
            vol.filepath = str(path)
            obj = bpy.data.objects.new(vname, vol)
            scene.collection.objects.link(obj)
            if scale is not None:
                obj.scale = scale
            vol.nubis_cloud.enabled = True
        bpy.ops.wm.save_as_mainfile(filepath=str(d / f"{name}.blend"))
    print(json.dumps({"blends": sorted(blend_specs(vdbs))}))


def helper_check_exr(repo: Path, path: Path) -> None:
    _helper_path(repo)
    import numpy as np

    from nubis_addon.core import imageio

    px = imageio.read_image(path)
    print(json.dumps({"finite": bool(np.isfinite(px).all()), "max": float(np.nanmax(px)), "shape": px.shape}))


# ---- the paint probes, run inside a child bpy process ----------------------------------------------------------


def _el(x, y, start=False, pressure=1.0):
    return {
        "name": "",
        "location": (x, y, 1500.0),
        "mouse": (0.0, 0.0),
        "mouse_event": (0.0, 0.0),
        "pressure": pressure,
        "size": 0.0,
        "x_tilt": 0.0,
        "y_tilt": 0.0,
        "time": 0.0,
        "is_start": start,
    }


def _line(*xys, pressure=1.0):
    return [_el(float(x), float(y), i == 0, pressure) for i, (x, y) in enumerate(xys)]


INF, NAN = float("inf"), float("nan")
BASE = dict(channel="COVERAGE", radius=2500.0, strength=1.0)


def paint_specs() -> dict[str, tuple[str, str, Callable[[], list[dict]]]]:
    """name -> (expect, preset, the operator calls' keyword arguments; the last call is the probe)."""
    s = _line

    def one(expect, preset="clear_sky", **kw):
        return expect, preset, lambda: [{**BASE, **kw}]

    return {
        "inside to (1e12, 0)": one("work", stroke=s((0, 0), (1e12, 0))),
        "inside to (0, -1e12)": one("work", stroke=s((0, 0), (0, -1e12))),
        "inside to (1e12, 1e12)": one("work", stroke=s((1000, 1000), (1e12, 1e12))),
        "across from -1e12 to 1e12": one("work", stroke=s((-1e12, 5000), (1e12, 5000))),
        "inside to inf": one("refuse", stroke=s((0, 0), (INF, 0))),
        "inside to -inf": one("refuse", stroke=s((0, 0), (-INF, 0))),
        "inside to nan": one("refuse", stroke=s((0, 0), (NAN, 0))),
        "inside to y nan": one("refuse", stroke=s((0, 0), (0, NAN))),
        "inside to 3.4e38": one("refuse", stroke=s((0, 0), (3.4e38, 0))),
        "single point far outside": one("refuse", stroke=s((1e12, 1e12))),
        "single point inside": one("work", stroke=s((0, 0))),
        "radius 1e-300": one("refuse", radius=1e-300, stroke=s((0, 0), (100, 0))),
        "radius 0": one("refuse", radius=0.0, stroke=s((0, 0), (100, 0))),
        "radius -5": one("refuse", radius=-5.0, stroke=s((0, 0), (100, 0))),
        "radius inf": one("refuse", radius=INF, stroke=s((0, 0), (100, 0))),
        "radius nan": one("refuse", radius=NAN, stroke=s((0, 0), (100, 0))),
        "radius 1e9": one("refuse", radius=1e9, stroke=s((0, 0), (100, 0))),
        "radius 1e30 (huge)": one("refuse", radius=1e30, stroke=s((0, 0), (100, 0))),
        "radius 70000 (the whole field)": one("work", radius=70000.0, stroke=s((0, 0), (100, 0))),
        "radius 70 (about half a pixel)": one("work", radius=70.0, stroke=s((0, 0), (1000, 0))),
        "strength 5": one("work", strength=5.0, stroke=s((0, 0), (100, 0))),
        "strength 0": one("refuse", strength=0.0, stroke=s((0, 0), (100, 0))),
        "strength -1": one("refuse", strength=-1.0, stroke=s((0, 0), (100, 0))),
        "strength nan": one("refuse", strength=NAN, stroke=s((0, 0), (100, 0))),
        "strength inf": one("either", strength=INF, stroke=s((0, 0), (100, 0))),
        "pressure 5": one("work", stroke=s((0, 0), (3000, 0), pressure=5.0)),
        "pressure nan": one("refuse", stroke=s((0, 0), (3000, 0), pressure=NAN)),
        "pressure -1": one("either", stroke=s((0, 0), (3000, 0), pressure=-1.0)),
        "empty stroke": one("refuse", stroke=[]),
        "2 million points": ("either", "clear_sky", lambda: [{**BASE, "stroke": _many(2_000_000)}]),
        "zigzag of 20000 points (over a million dabs)": (
            "refuse",
            "clear_sky",
            lambda: [{**BASE, "stroke": s(*[((-30000, 30000)[i % 2], 100 * (i % 50)) for i in range(20_000)])}],
        ),
        "channel TYPE": one("work", channel="TYPE", stroke=s((-3000, 0), (3000, 0))),
        "channel PRECIPITATION": one("work", channel="PRECIPITATION", stroke=s((-3000, 0), (3000, 0))),
        "channel STORM without a superstorm": one("refuse", channel="STORM", stroke=s((-3000, 0), (3000, 0))),
        "channel STORM in the superstorm preset": one(
            "either", "superstorm", channel="STORM", stroke=s((-3000, 0), (3000, 0))
        ),
        "mode SUBTRACT": one("work", mode="SUBTRACT", stroke=s((-3000, 0), (3000, 0))),
        "mode SMOOTH": (
            "work",
            "clear_sky",
            lambda: [
                {**BASE, "stroke": s((-3000, 0), (3000, 0))},
                {**BASE, "mode": "SMOOTH", "stroke": s((-3000, 500), (3000, 500))},
            ],
        ),
        "falloff CONSTANT": one("work", falloff="CONSTANT", stroke=s((-3000, 0), (3000, 0))),
        "falloff LINEAR": one("work", falloff="LINEAR", stroke=s((-3000, 0), (3000, 0))),
        "into a paint layer of another channel": (
            "refuse",
            "clear_sky",
            lambda: [
                {**BASE, "layer": "Mine", "stroke": s((0, 0), (100, 0))},
                {**BASE, "channel": "TYPE", "layer": "Mine", "stroke": s((0, 0), (100, 0))},
            ],
        ),
        "into a worley layer": one("refuse", layer="Coverage", stroke=s((0, 0), (100, 0))),
    }


def _many(n: int) -> list[dict]:
    """n points along a line over the field, 3 cm apart."""
    return [_el(-30000.0 + 60000.0 * i / n, 0.0, i == 0) for i in range(n)]


def helper_paint(repo: Path, name: str) -> None:
    """One paint probe: the scene made, the calls made, one HR-RESULT line on stdout."""
    _helper_path(repo)
    import bpy
    import numpy as np

    import nubis_addon
    from nubis_addon.blender import ensure_registered
    from nubis_addon.blender.scene import datafield, sceneparams, scenepresets
    from nubis_addon.core import paint
    from nubis_addon.core.presets import load_preset
    from nubis_addon.render.gpu_context import ensure_gpu_context

    expect, preset, calls = paint_specs()[name]
    nubis_addon.register()
    ensure_gpu_context()
    bpy.ops.wm.read_factory_settings(use_empty=True)
    ensure_registered()
    scene = bpy.context.scene
    scenepresets.apply_preset(scene, load_preset(preset))
    kwargs = calls()
    for kw in kwargs[:-1]:
        assert bpy.ops.nubis.paint_field(**kw) == {"FINISHED"}, kw
    n_before = {x.name: len(x.dabs) for x in scene.nubis.layers if x.kind == "PAINT"}
    start = time.perf_counter()
    try:
        status = bpy.ops.nubis.paint_field(**kwargs[-1])
    except RuntimeError as err:
        secs = time.perf_counter() - start
        print(RESULT_TAG + json.dumps({"status": "refused", "message": str(err).strip(), "secs": secs}))
        return
    secs = time.perf_counter() - start
    if status != {"FINISHED"}:
        print(RESULT_TAG + json.dumps({"status": "cancelled", "message": str(status), "secs": secs}))
        return
    # What it painted: every dab of every paint layer finite, its centre where its disc touches the field,
    # its strength within -1 to 1; the fields finite; the stroke laid dabs.
    grid = paint.Grid.of(sceneparams.params_from_scene(scene.nubis))
    problems, laid = [], 0
    for layer in scene.nubis.layers:
        if layer.kind != "PAINT":
            continue
        dabs = datafield.paint_dabs(layer)
        laid += len(dabs) - n_before.get(layer.name, 0)
        if not np.isfinite(dabs).all():
            problems.append(f"non-finite dabs in '{layer.name}'")
            continue
        for x, y, r, st, *_ in dabs:
            x0, x1, y0, y1 = grid.reach(r)
            if not (x0 <= x <= x1 and y0 <= y <= y1):
                problems.append(f"a dab at ({x:g}, {y:g}) r {r:g} lies off the field")
                break
            if not -1.0 <= st <= 1.0:
                problems.append(f"a dab of strength {st:g}")
                break
    for k, plane in enumerate(datafield.read_fields(scene.nubis)):
        if not np.isfinite(plane).all():
            problems.append(f"field {'ABC'[k]} holds non-finite values")
    if laid <= 0 and kwargs[-1].get("mode") != "SMOOTH":
        problems.append("no dab was laid")
    print(RESULT_TAG + json.dumps({"status": "finished", "problem": "; ".join(problems), "laid": laid, "secs": secs}))


# ---- the probe lists ---------------------------------------------------------------------------------------------

GARBAGE_SEEDS = 8
FLIP_SEEDS = 12


def cut_points(n: int) -> list[int]:
    """10 cuts of an n-byte file: in the header, several between 64 and 350 bytes, inside, near the end."""
    return sorted({8, 64, 90, 150, 230, 349, 1000, n // 2, n - 16, n - 1})


def blend_specs(vdbs: Path) -> dict[str, list[tuple[str, Path, tuple | None]]]:
    good = vdbs / "good.vdb"
    return {
        "good": [("Cloud", good, None)],
        "cut at 2000 bytes": [("A good", good, None), ("B cut", vdbs / "cut_2000.vdb", None)],
        "missing file": [("Gone", vdbs / "missing.vdb", None)],
        "scaled to zero on y": [("Flat", good, (1.0, 0.0, 1.0))],
        "five marked": [(f"Cloud {k}", vdbs / f"good_{k}.vdb", None) for k in range(1, 6)],
        "nameless grid": [("Nameless", vdbs / "nameless.vdb", None)],
    }


class Round:
    def __init__(self, repo: Path, work: Path, python: str):
        self.repo, self.work, self.python = repo, work, python
        self.vdbs = work / "vdbs"
        self.blends = work / "blends"
        self.out = work / "out"
        self.scratch = work / "scratch"
        self.size = 0
        self.notes: list[str] = []

    # -- running ---------------------------------------------------------------------------------------------

    def cli(self, args: list[str], timeout: float) -> Callable[[], Run]:
        return lambda: run_child([self.python, "-m", "nubis_addon", *args], self.repo, self.scratch, timeout)

    def helper(self, *args: str, timeout: float = TIMEOUT_RENDER) -> Run:
        argv = [self.python, str(HERE), "--repo", str(self.repo), "--helper", *args]
        return run_child(argv, self.repo, self.scratch, timeout)

    def prepare(self, classes) -> None:
        self.out.mkdir(parents=True, exist_ok=True)
        if "vdb" in classes:
            r = self.helper("make-vdbs", str(self.vdbs))
            if r.rc != 0:
                raise SystemExit(f"making the VDB files failed (exit {r.rc}):\n{r.err[-3000:]}")
            self.size = json.loads(r.out.strip().splitlines()[-1])["size"]
            os.mkfifo(self.vdbs / "pipe.vdb")
            self.blends.mkdir(parents=True, exist_ok=True)
            r = self.helper("make-blends", str(self.blends), str(self.vdbs))
            if r.rc != 0:
                raise SystemExit(f"making the .blend files failed (exit {r.rc}):\n{r.err[-3000:]}")

    # -- vdb -------------------------------------------------------------------------------------------------

    def vdb_files(self) -> list[tuple[str, list[Path], str]]:
        """(label, the --vdb files, expect) for the render probes."""
        v = self.vdbs
        size = self.size or 14533
        files: list[tuple[str, list[Path], str]] = []
        files += [(f"cut at {c} of {size} bytes", [v / f"cut_{c}.vdb"], "refuse") for c in cut_points(size)]
        files += [(f"64 bytes + garbage, seed {s}", [v / f"garbage_{s}.vdb"], "refuse") for s in range(GARBAGE_SEEDS)]
        files += [(f"bytes changed in place, seed {s}", [v / f"flip_{s}.vdb"], "either") for s in range(FLIP_SEEDS)]
        files += [
            ("empty file", [v / "empty.vdb"], "refuse"),
            ("text file", [v / "text.vdb"], "refuse"),
            ("folder", [v / "folder.vdb"], "refuse"),
            ("FIFO", [v / "pipe.vdb"], "refuse"),
            ("/dev/zero", [Path("/dev/zero")], "refuse"),
            ("name of 304 bytes", [v / ("n" * 300 + ".vdb")], "refuse"),
            ("missing file", [v / "missing.vdb"], "refuse"),
            ('grid named ""', [v / "nameless.vdb"], "refuse"),
            ("vector grid only", [v / "bad" / "vec.vdb"], "refuse"),
            ("empty grid", [v / "bad" / "empty.vdb"], "refuse"),
            ("negative values", [v / "bad" / "neg.vdb"], "refuse"),
            ("a NaN value", [v / "bad" / "nan.vdb"], "refuse"),
            ("sheared transform", [v / "bad" / "shear.vdb"], "refuse"),
            ("non-uniform voxels", [v / "bad" / "stretch.vdb"], "refuse"),
            ("frustum transform", [v / "frustum.vdb"], "refuse"),
            ("two voxels 60,000 apart", [v / "far_60000.vdb"], "refuse"),
            ("two voxels 16,000 apart", [v / "far_16000.vdb"], "work"),
            ("active tile fill of 4096^3", [v / "tiles_4096.vdb"], "refuse"),
            ("5 files", [v / f"good_{k}.vdb" for k in range(1, 6)], "refuse"),
            ("4 files", [v / f"good_{k}.vdb" for k in range(1, 5)], "work"),
            ("the good file", [v / "good.vdb"], "work"),
            ("the same good file twice", [v / "good.vdb", v / "good.vdb"], "either"),
        ]
        return files

    def vdb_probes(self) -> list[Probe]:
        probes = []
        o = self.out / "vdb"
        o.mkdir(parents=True, exist_ok=True)
        vdbargs = lambda paths: [a for p in paths for a in ("--vdb", str(p))]  # noqa: E731
        for k, (label, paths, expect) in enumerate(self.vdb_files()):
            out = o / f"render_{k:02d}.png"
            probes.append(
                Probe(
                    "vdb",
                    f"render: {label}",
                    expect,
                    self.cli(["render", *vdbargs(paths), *SIZE, "--out", str(out)], TIMEOUT_RENDER),
                    check=png_at(out),
                    after=nothing_left(out),
                )
            )
        # Values of 1e7 per metre: drawn, and the EXR finite.
        exr = o / "hot_1e7.exr"
        probes.append(
            Probe(
                "vdb",
                "render: values of 1e7 (EXR)",
                "work",
                self.cli(["render", "--vdb", str(self.vdbs / "hot_1e7.vdb"), *SIZE, "--out", str(exr)], TIMEOUT_RENDER),
                check=self.finite_exr(exr),
            )
        )
        # benchmark: the refusals (each before any work) and the good file once.
        bench = {
            "cut at 64",
            "cut at 150",
            "cut at 349",
            f"cut at {(self.size or 14533) - 1}",
            "64 bytes + garbage, seed 0",
            "64 bytes + garbage, seed 1",
            "bytes changed in place, seed 1",
            "empty file",
            "text file",
            "folder",
            "FIFO",
            "/dev/zero",
            "name of 304 bytes",
            "missing file",
            'grid named ""',
            "vector grid only",
            "negative values",
            "a NaN value",
            "sheared transform",
            "non-uniform voxels",
            "frustum transform",
            "two voxels 60,000 apart",
            "active tile fill of 4096^3",
            "5 files",
            "the good file",
        }
        for k, (label, paths, expect) in enumerate(self.vdb_files()):
            if not any(label == b or label.startswith(b + " of") for b in bench):
                continue
            out = o / f"bench_{k:02d}"
            probes.append(
                Probe(
                    "vdb",
                    f"benchmark: {label}",
                    expect,
                    self.cli(["benchmark", *vdbargs(paths), *SIZE, "--out", str(out)], TIMEOUT_RENDER),
                    check=exists(out / "benchmark.json"),
                    after=nothing_left(out),
                )
            )
        return probes + self.compare_probes(o, vdbargs) + self.blend_probes(o)

    def compare_probes(self, o: Path, vdbargs) -> list[Probe]:
        """compare --draft: slow (Cycles), a few."""
        probes = []
        for label in ("the good file", "cut at 150", "64 bytes + garbage, seed 2", "a NaN value", "5 files"):
            k, (lab, paths, expect) = next(
                (k, x) for k, x in enumerate(self.vdb_files()) if x[0] == label or x[0].startswith(label + " of")
            )
            out = o / f"compare_{k:02d}"
            probes.append(
                Probe(
                    "vdb",
                    f"compare --draft: {lab}",
                    expect,
                    self.cli(["compare", "--draft", *vdbargs(paths), *SIZE, "--out", str(out)], TIMEOUT_RENDER),
                    check=exists(out / "metrics.json"),
                    after=nothing_left(out),
                )
            )
        return probes

    def blend_probes(self, o: Path) -> list[Probe]:
        """VDB clouds in saved .blend files."""
        probes = []
        expects = {"good": "work", "five marked": "work"}
        for k, name in enumerate(blend_specs(self.vdbs)):
            out = o / f"blend_{k:02d}.png"
            check = png_at(out)
            if name == "five marked":
                check = self.five_marked(out)
            probes.append(
                Probe(
                    "vdb",
                    f"render --blend: {name}",
                    expects.get(name, "refuse"),
                    self.cli(
                        ["render", "--blend", str(self.blends / f"{name}.blend"), *SIZE, "--out", str(out)],
                        TIMEOUT_RENDER,
                    ),
                    check=check,
                    after=nothing_left(out),
                )
            )
        self.notes.append(
            "not probed: a .blend whose Volume file is cut in its first few hundred bytes; Blender's own "
            "loader (not the extension's code) takes 10-30 s and GBs on those (docs/vdb.md, docs/limits.md)"
        )
        return probes

    def finite_exr(self, exr: Path) -> Callable[[Run], str | None]:
        def check(_r: Run) -> str | None:
            if not exr.is_file():
                return f"'{exr.name}' was not written"
            h = self.helper("check-exr", str(exr), timeout=TIMEOUT)
            if h.rc != 0:
                return f"the EXR could not be read ({h.err.strip().splitlines()[-1:]})"
            info = json.loads(h.out.strip().splitlines()[-1])
            return None if info["finite"] else "the EXR holds non-finite values"

        return check

    @staticmethod
    def five_marked(out: Path) -> Callable[[Run], str | None]:
        def check(r: Run) -> str | None:
            why = is_png(out)
            if why:
                return why
            notes = [x for x in r.err.splitlines() if x.startswith("nubis: note:")]
            if len(notes) != 1 or "Cloud 5" not in notes[0] or "left out" not in notes[0]:
                return f"{len(notes)} 'nubis: note:' lines, not one saying 'Cloud 5' is left out"
            return None

        return check

    # -- paint -----------------------------------------------------------------------------------------------

    def paint_probes(self) -> list[Probe]:
        probes = []
        for name, (expect, _preset, _calls) in paint_specs().items():
            probes.append(Probe("paint", f"paint: {name}", expect, self.paint_runner(name)))
        return probes

    def paint_runner(self, name: str) -> Callable[[], Run]:
        def run() -> Run:
            r = self.helper("paint", name, timeout=TIMEOUT)
            return paint_result(r)

        return run

    # -- presets ---------------------------------------------------------------------------------------------

    def preset_rows(self) -> list[tuple[str, str, str]]:
        """(label, the dabs value as TOML, expect); the good second row keeps the layer a real one."""
        good = "[0.0, 0.0, 2500.0, 1.0, 0, 0, 0]"
        rows = [
            ("radius 1e-300", "[0.0, 0.0, 1e-300, 1.0, 0, 0, 1]", "refuse"),
            ("radius 1e300", "[0.0, 0.0, 1e300, 1.0, 0, 0, 1]", "refuse"),
            ("radius -1", "[0.0, 0.0, -1.0, 1.0, 0, 0, 1]", "refuse"),
            ("radius 0", "[0.0, 0.0, 0.0, 1.0, 0, 0, 1]", "refuse"),
            ("radius 1e400 (inf)", "[0.0, 0.0, 1e400, 1.0, 0, 0, 1]", "refuse"),
            ("radius -1e400 (-inf)", "[0.0, 0.0, -1e400, 1.0, 0, 0, 1]", "refuse"),
            ("radius nan", "[0.0, 0.0, nan, 1.0, 0, 0, 1]", "refuse"),
            ("radius 2e7 (wider than any field)", "[0.0, 0.0, 2e7, 1.0, 0, 0, 1]", "refuse"),
            ("radius 0.001 (a millimetre)", "[0.0, 0.0, 0.001, 1.0, 0, 0, 1]", "work"),
            ("x 1e300", "[1e300, 0.0, 2500.0, 1.0, 0, 0, 1]", "refuse"),
            ("y 1e300", "[0.0, 1e300, 2500.0, 1.0, 0, 0, 1]", "refuse"),
            ("x -1e300", "[-1e300, 0.0, 2500.0, 1.0, 0, 0, 1]", "refuse"),
            ("x 1e9", "[1e9, 0.0, 2500.0, 1.0, 0, 0, 1]", "refuse"),
            ("y -1e9", "[0.0, -1e9, 2500.0, 1.0, 0, 0, 1]", "refuse"),
            ("x 1e400 (inf)", "[1e400, 0.0, 2500.0, 1.0, 0, 0, 1]", "refuse"),
            ("y nan", "[0.0, nan, 2500.0, 1.0, 0, 0, 1]", "refuse"),
            ("x 1e7 (off this field, within reach)", "[1e7, 0.0, 2500.0, 1.0, 0, 0, 1]", "work"),
            ("strength 5", "[0.0, 0.0, 2500.0, 5.0, 0, 0, 1]", "refuse"),
            ("strength -5", "[0.0, 0.0, 2500.0, -5.0, 0, 0, 1]", "refuse"),
            ("strength nan", "[0.0, 0.0, 2500.0, nan, 0, 0, 1]", "refuse"),
            ("strength -1 (a subtracting dab)", "[0.0, 0.0, 2500.0, -1.0, 0, 0, 1]", "work"),
            ("falloff 9", "[0.0, 0.0, 2500.0, 1.0, 9, 0, 1]", "refuse"),
            ("falloff -1", "[0.0, 0.0, 2500.0, 1.0, -1, 0, 1]", "refuse"),
            ("falloff 1.5", "[0.0, 0.0, 2500.0, 1.0, 1.5, 0, 1]", "refuse"),
            ("mode 9", "[0.0, 0.0, 2500.0, 1.0, 0, 9, 1]", "refuse"),
            ("mode 1 (smooth) and falloff 2", "[0.0, 0.0, 2500.0, 1.0, 2, 1, 1]", "work"),
            ("start 2", "[0.0, 0.0, 2500.0, 1.0, 0, 0, 2]", "refuse"),
            ("start 1e400", "[0.0, 0.0, 2500.0, 1.0, 0, 0, 1e400]", "refuse"),
            ("a row of 6", "[0.0, 0.0, 2500.0, 1.0, 0, 0]", "refuse"),
            ("a row of 8", "[0.0, 0.0, 2500.0, 1.0, 0, 0, 1, 1]", "refuse"),
            ("an empty row", "[]", "refuse"),
            ("a number for a row", "5", "refuse"),
            ("a table for a row", "{ x = 1 }", "refuse"),
            ("strings", '["0", "0", "2500", "1", "0", "0", "1"]', "refuse"),
            ("booleans", "[true, false, 2500.0, 1.0, 0, 0, true]", "refuse"),
            ("an integer 10**400", f"[0, {10**400}, 2500.0, 1.0, 0, 0, 1]", "refuse"),
            ("a date", "[1979-05-27, 0.0, 2500.0, 1.0, 0, 0, 1]", "refuse"),
            ("deep nesting", "[" * 200 + "]" * 200, "refuse"),
        ]
        return [(label, f"[\n  {row},\n  {good},\n]", expect) for label, row, expect in rows] + [
            ("dabs a number", "5", "refuse"),
            ("dabs a string", '"x"', "refuse"),
            ("dabs empty", "[]", "work"),
            (
                "a good small paint layer",
                "[\n  [-3000.0, 0.0, 2500.0, 1.0, 0, 0, 1],\n  [3000.0, 0.0, 2500.0, 0.5, 1, 0, 0],\n]",
                "work",
            ),
        ]

    def preset_probes(self) -> list[Probe]:
        base = (self.repo / "presets" / "clear_sky.toml").read_text()
        d = self.work / "presets"
        d.mkdir(parents=True, exist_ok=True)
        o = self.out / "presets"
        o.mkdir(parents=True, exist_ok=True)
        probes = []

        def add(k: int, label: str, text: str, expect: str) -> None:
            path = d / f"p{k:02d}.toml"
            path.write_text(text)
            out = o / f"p{k:02d}.png"
            probes.append(
                Probe(
                    "presets",
                    f"preset: {label}",
                    expect,
                    self.cli(["render", "--preset", str(path), *SIZE, "--out", str(out)], TIMEOUT_RENDER),
                    check=png_at(out),
                    after=nothing_left(out),
                )
            )

        layer = '\n[[field.layers]]\nname = "Paint Coverage"\nkind = "{kind}"\nchannel = "coverage"\ndabs = {dabs}\n'
        rows = self.preset_rows()
        for k, (label, dabs, expect) in enumerate(rows):
            add(k, label, base + layer.format(kind="paint", dabs=dabs), expect)
        k = len(rows)
        add(k, "a perlin layer with dabs", base + layer.format(kind="perlin", dabs=rows[-1][1]), "refuse")
        # 1,000,001 rows, written as one string (about 20 MB).
        many = "[\n" + "[0,0,2500,1,0,0,0],\n" * 1_000_001 + "]"
        add(k + 1, "1,000,001 rows", base + layer.format(kind="paint", dabs=many), "refuse")
        return probes

    # -- bake ------------------------------------------------------------------------------------------------

    BAKE_VOXEL = "60"

    def bake_probes(self) -> list[Probe]:
        specs = [
            # name, action, when ("start": 1 s after launch; "mid": 1 s into the bake), frames, expect
            ("no action (control)", None, None, False, "work"),
            # 1 s after launch the run is still starting (importing bpy): the bake then finds no folder and
            # makes it, as it makes any missing output folder (core/fsutil.py), or says it cannot.
            ("remove the folder 1 s after launch", "rmdir", "start", False, "either"),
            ("remove the folder during the bake", "rmdir", "mid", False, "refuse"),
            ("replace the folder by a file 1 s after launch", "file", "start", False, "either"),
            ("replace the folder by a file during the bake", "file", "mid", False, "refuse"),
            ("chmod the folder 0o500 during the bake", "chmod", "mid", False, "refuse" if os.geteuid() else "either"),
            ("rename the folder during the bake", "rename", "mid", False, "refuse"),
            ("SIGINT during the bake", "SIGINT", "mid", False, "refuse"),
            ("SIGTERM during the bake", "SIGTERM", "mid", False, "refuse"),
            ("SIGHUP during the bake", "SIGHUP", "mid", False, "refuse"),
            ("SIGINT 1 s after launch", "SIGINT", "start", False, "refuse"),
            ("--frames 1-3, no action (control)", None, None, True, "work"),
            ("--frames 1-3, remove the folder mid-way", "rmdir", "mid", True, "refuse"),
            ("--frames 1-3, SIGTERM mid-way", "SIGTERM", "mid", True, "refuse"),
        ]
        self._bake_timing: dict[str, float] = {}
        return [self.bake_probe(*spec) for spec in specs]

    def bake_probe(self, name: str, action, when, frames: bool, expect: str) -> Probe:
        slug = re.sub(r"[^a-z0-9]+", "-", name.lower()).strip("-")
        top = self.work / "bake" / slug
        folder = top / "out"
        renamed = top / "out-renamed"
        out = folder / ("clouds_####.vdb" if frames else "clouds.vdb")
        args = ["bake", "--preset", "default", "--voxel-size", self.BAKE_VOXEL, "--out", str(out)]
        if frames:
            args += ["--frames", "1-3"]
        codes = {"SIGINT": (130,), "SIGTERM": (143,), "SIGHUP": (129,)}.get(action or "", ())

        def run() -> Run:
            shutil.rmtree(top, ignore_errors=True)
            folder.mkdir(parents=True)
            child = Child([self.python, "-m", "nubis_addon", *args], self.repo, self.scratch)
            notes = []
            if action:
                if when == "start":
                    at = 1.0
                else:  # one second into the work: the launch's cost measured by the control run
                    at = self._bake_timing.get("startup", 5.0) + (
                        1.5 * self._bake_timing.get("bake", 4.0) if frames else 1.0
                    )
                while child.elapsed() < at and child.proc.poll() is None:
                    time.sleep(0.02)
                if child.proc.poll() is not None:
                    notes.append(f"the run had ended before the action at {at:.1f} s")
                t_act = child.elapsed()
                if action == "rmdir":
                    shutil.rmtree(folder)
                elif action == "file":
                    shutil.rmtree(folder)
                    folder.write_text("not a folder\n")
                elif action == "chmod":
                    os.chmod(folder, 0o500)
                elif action == "rename":
                    folder.rename(renamed)
                else:
                    child.proc.send_signal(getattr(signal, action))
                notes.append(f"{action} at {t_act:.1f} s")
            r = child.finish(TIMEOUT)
            if action:
                notes.append(f"ended {r.secs - t_act:.1f} s after it")
            if action == "chmod" and folder.is_dir():
                os.chmod(folder, 0o700)
            r.notes = notes
            if action is None and r.rc == 0:
                m = re.search(r"in ([\d.]+) s ->", r.out)
                if m:
                    seconds = float(m.group(1)) / (3 if frames else 1)
                    self._bake_timing.setdefault("bake", seconds)
                    self._bake_timing.setdefault("startup", max(r.secs - float(m.group(1)), 1.0))
            return r

        def check(_r: Run) -> str | None:
            if frames:
                missing = [f"clouds_{k:04d}.vdb" for k in (1, 2, 3) if not (folder / f"clouds_{k:04d}.vdb").is_file()]
                return f"{missing} were not written" if missing else None
            return None if (folder / "clouds.vdb").is_file() else "clouds.vdb was not written"

        def after(r: Run, refused: bool) -> str | None:
            problems = []
            for place in (top, folder, renamed):
                if place.is_dir():
                    staging = [p.name for p in place.iterdir() if p.name.startswith(".nubis-tmp-")]
                    if staging:
                        problems.append(f"staging left in '{place.name}': {staging[0]}")
            if refused:
                for place in (folder, renamed):
                    if place.is_dir():
                        vdbs = [p.name for p in place.rglob("*.vdb")]
                        if vdbs:
                            problems.append(f"'{vdbs[0]}' written in '{place.name}' by a failed run")
                if action == "rmdir" and folder.exists():
                    problems.append("the removed folder was made again")
                if action == "file" and (not folder.is_file() or folder.read_text() != "not a folder\n"):
                    problems.append("the file in the folder's place was changed")
            return "; ".join(problems) or None

        return Probe(
            "bake",
            f"bake: {name}",
            expect,
            run,
            check=check,
            after=after,
            interrupted_ok=codes,
            describe=" ".join(args),
        )


def paint_result(r: Run) -> Run:
    """A paint child's run as a command's: a refusal becomes exit 1 with its one `nubis: error:` line (when
    the operator's message is one line), a finished stroke exit 0 (or a defect its check names)."""
    lines = [x for x in r.out.splitlines() if x.startswith(RESULT_TAG)]
    if r.timed_out or not lines:
        return r
    if r.rc != 0:  # a crash after the result: classify() says what ended it
        return r
    res = json.loads(lines[-1][len(RESULT_TAG) :])
    r = Run(r.rc, r.out, r.err, res["secs"], False, wall=r.wall)
    if res["status"] == "refused":
        text = res["message"]
        text = text.removeprefix("Error: ")
        if "\n" in text or "Traceback" in text or text.startswith("Python:"):
            r.err += "\n[the operator's message, not one line:]\n" + res["message"]
            r.rc = 3
        else:
            r.err += f"\nnubis: error: {text}"
            r.rc = 1
    elif res["status"] == "cancelled":
        r.err += f"\n[cancelled without an ERROR report: {res['message']}]"
        r.rc = 4
    else:
        r.rc = 0
        r.out += f"\npainted {res['laid']} dabs in {res['secs']:.2f} s"
        r.notes.append(res.get("problem", ""))
    return r


def paint_check(r: Run) -> str | None:
    return r.notes[0] if r.notes and r.notes[0] else None


# ---- the round -------------------------------------------------------------------------------------------------


def machine() -> str:
    mem = {}
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            key, value = line.split(":", 1)
            mem[key] = int(value.split()[0]) * 1024
    except OSError:
        pass
    gib = lambda k: f"{mem.get(k, 0) / 2**30:.1f} GiB"  # noqa: E731
    load = ", ".join(f"{x:.2f}" for x in os.getloadavg())
    return (
        f"nproc {os.cpu_count()}, memory {gib('MemTotal')} total, {gib('MemFree')} free, "
        f"{gib('MemAvailable')} available, load {load}"
    )


def checkout(repo: Path) -> str:
    """The commit probed and whether the tree differs from it (best effort: an export has no git)."""
    try:
        head = subprocess.run(
            ["git", "-C", str(repo), "log", "-1", "--format=%h %cd", "--date=iso"],
            capture_output=True,
            text=True,
            timeout=30,
        )
        if head.returncode != 0:
            return "not a git checkout"
        dirty = subprocess.run(
            ["git", "-C", str(repo), "status", "--porcelain", "--untracked-files=no"],
            capture_output=True,
            text=True,
            timeout=30,
        ).stdout.splitlines()
        return f"{head.stdout.strip()}, {len(dirty)} tracked file(s) changed"
    except (OSError, subprocess.SubprocessError):
        return "unknown"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repo", type=Path, default=ROOT, help="the checkout to probe (default: this one)")
    ap.add_argument("--only", help="comma-separated classes: " + ",".join(CLASSES))
    ap.add_argument("--match", help="only probes whose name holds this text")
    ap.add_argument("--list", action="store_true", help="list the probes and exit")
    ap.add_argument("--keep", action="store_true", help="keep the scratch folder")
    ap.add_argument("--python", default=sys.executable, help="the Python with bpy (default: this one)")
    ap.add_argument("--helper", nargs="+", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    repo = args.repo.resolve()

    if args.helper:
        what, *rest = args.helper
        if what == "make-vdbs":
            helper_make_vdbs(repo, Path(rest[0]))
        elif what == "make-blends":
            helper_make_blends(repo, Path(rest[0]), Path(rest[1]))
        elif what == "check-exr":
            helper_check_exr(repo, Path(rest[0]))
        elif what == "paint":
            helper_paint(repo, rest[0])
        return 0

    classes = tuple(c for c in (args.only.split(",") if args.only else CLASSES) if c)
    unknown = set(classes) - set(CLASSES)
    if unknown:
        ap.error(f"unknown class {sorted(unknown)}: use {', '.join(CLASSES)}")
    work = Path(tempfile.mkdtemp(prefix="nubis-hostile-round-"))
    rnd = Round(repo, work, args.python)
    t0 = time.monotonic()
    try:
        print(f"hostile round on {repo} with {args.python}; scratch {work}")
        print(f"machine: {machine()}")
        print(f"checkout: {checkout(repo)}")
        if not args.list:
            rnd.prepare(classes)
        probes: list[Probe] = []
        for c in classes:
            probes += {
                "vdb": rnd.vdb_probes,
                "paint": rnd.paint_probes,
                "presets": rnd.preset_probes,
                "bake": rnd.bake_probes,
            }[c]()
        for p in probes:
            if p.cls == "paint":
                p.check = paint_check
        if args.match:
            probes = [p for p in probes if args.match.lower() in p.name.lower()]
        if args.list:
            for p in probes:
                print(f"{p.cls:8} {p.expect:7} {p.name}")
            print(f"{len(probes)} probes")
            return 0
        outcomes: list[Outcome] = []
        for i, p in enumerate(probes, 1):
            r = p.run()
            o = classify(p, r)
            outcomes.append(o)
            shown = o.message or (o.run.out.strip().splitlines()[-1] if o.run.out.strip() else "")
            extra = f" [{'; '.join(n for n in r.notes if n)}]" if p.cls == "bake" and r.notes else ""
            why = f" ({o.reason})" if o.reason else ""
            if p.cls == "paint" and r.wall:
                extra += f" [the operator; the child process ran {r.wall:.1f} s]"
            print(f"{i:3d}/{len(probes)} {o.kind:8} {o.secs:6.1f} s  {p.name}{why}{extra}", flush=True)
            if shown:
                print(f"             {shown[:300]}", flush=True)
        report(outcomes, classes, rnd.notes, time.monotonic() - t0)
        print(f"checkout at the end: {checkout(repo)}")
        return 0
    finally:
        if args.keep:
            print(f"kept {work}")
        else:
            for p in work.rglob("*"):  # a chmod 0o500 folder of a bake probe, should one be left
                if p.is_dir() and not p.is_symlink():
                    try:
                        os.chmod(p, 0o700)
                    except OSError:
                        pass
            shutil.rmtree(work, ignore_errors=True)


def report(outcomes: list[Outcome], classes, notes: list[str], seconds: float) -> None:
    defects = [o for o in outcomes if o.kind == "defect"]
    print()
    if defects:
        print(f"defects ({len(defects)}):")
        for o in defects:
            print(f"- [{o.probe.cls}] {o.probe.name}: {o.reason} (exit {o.run.rc}, {o.secs:.1f} s)")
            tail = [x for x in o.run.err.splitlines() if x.strip()][-5:]
            for line in tail:
                print(f"    | {line[:400]}{' ...' if len(line) > 400 else ''}")
        print()
    slow = [o for o in outcomes if o.kind == "sentence" and o.secs > SLOW_S and o.probe.cls != "bake"]
    if slow:
        print(f"refusals that took over {SLOW_S:g} s (counted as sentences):")
        for o in slow:
            print(f"- [{o.probe.cls}] {o.probe.name}: {o.secs:.1f} s")
        print()
    for n in notes:
        print(f"note: {n}")
    print()
    print("| class | probes | sentence | works | defect |")
    print("|---|---:|---:|---:|---:|")
    totals = [0, 0, 0, 0]
    for c in classes:
        of = [o for o in outcomes if o.probe.cls == c]
        row = [len(of), *(sum(o.kind == k for o in of) for k in ("sentence", "works", "defect"))]
        totals = [a + b for a, b in zip(totals, row, strict=True)]
        print(f"| {c} | {' | '.join(map(str, row))} |")
    print(f"| total | {' | '.join(map(str, totals))} |")
    print()
    print(f"{totals[0]} probes in {seconds / 60:.1f} min; machine: {machine()}")


if __name__ == "__main__":
    sys.exit(main())
