"""An output folder removed, or replaced by a file, while a headless `bake` runs; a `benchmark --vdb` that
fails in its second stage. Each ends in one sentence and exit 1 (not `internal error: FileNotFoundError`),
with nothing of the run left anywhere: not beside the folder, not in the temporary folder.

The commands run as child processes (`python -m nubis_addon`), each with a TMPDIR of its own."""

from __future__ import annotations

import errno
import os
import pty
import re
import select
import shutil
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from conftest import ROOT
from vdb_helpers import write_cumulus

pytestmark = pytest.mark.process  # the process's contract with the system (pyproject.toml)


def _env(tmp_path: Path) -> dict:
    tmpdir = tmp_path / "tmpdir"
    tmpdir.mkdir(exist_ok=True)
    return dict(os.environ, TMPDIR=str(tmpdir))


def _start(args, env, stderr=subprocess.PIPE) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", "nubis_addon", *args],
        cwd=ROOT,
        env=env,
        stdout=subprocess.PIPE,
        stderr=stderr,
        text=True,
    )


def _wait_for(proc: subprocess.Popen, predicate, timeout: float = 300.0) -> None:
    end = time.monotonic() + timeout
    while not predicate():
        assert proc.poll() is None, f"the run ended before it got there: {proc.communicate()}"
        assert time.monotonic() < end, "timed out waiting for the run to get there"
        time.sleep(0.002)


def _take_away(folder: Path, how: str) -> None:
    if how == "moved away":  # `mv frames elsewhere`: what the run staged in it goes along
        folder.rename(folder.parent / "elsewhere")
        return
    # `rm -rf frames`: the run may write into the folder between rmtree's listing and its last rmdir (the
    # folder is still there then); a user's rm meets the same race, and runs again.
    for _ in range(50):
        try:
            shutil.rmtree(folder)
            break
        except OSError as err:
            if err.errno != errno.ENOTEMPTY:
                raise
    assert not folder.exists()
    if how == "replaced by a file":
        folder.write_text("not a folder")


def _sentence(folder: Path, how: str) -> str:
    said = "removed" if how == "moved away" else how
    fix = "move the file away, make the folder again" if how == "replaced by a file" else "make the folder again"
    return (
        f"nubis: error: the output folder '{folder}' was {said} while the bake ran: nothing was written; "
        f"{fix} and bake again"
    )


def _left_as_taken(tmp_path: Path, folder: Path, how: str) -> None:
    """Nothing of the run anywhere: the folder as the test left it, nothing beside it (or in the folder it
    was moved to) nor in TMPDIR."""
    beside = ["tmpdir"]
    if how == "replaced by a file":
        assert folder.read_text() == "not a folder"
        beside.append(folder.name)
    else:
        assert not folder.exists()
    if how == "moved away":
        assert list((tmp_path / "elsewhere").iterdir()) == []
        beside.append("elsewhere")
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(beside)
    assert list((tmp_path / "tmpdir").iterdir()) == []


class _Terminal:
    """The child's stderr on a terminal, so that it draws its progress bar: the test acts once the bake has
    evaluated its first tiles, however fast the machine sets up. A thread reads all along (a full terminal
    buffer would block the child)."""

    def __init__(self):
        self.leader, self.follower = pty.openpty()
        self.chunks: list[bytes] = []
        self.stop = threading.Event()
        self.reader = threading.Thread(target=self._drain, daemon=True)
        self.reader.start()

    def _drain(self):
        while not self.stop.is_set():
            if select.select([self.leader], [], [], 0.05)[0]:
                try:
                    self.chunks.append(os.read(self.leader, 4096))
                except OSError:
                    return

    def text(self) -> str:
        return b"".join(self.chunks).decode("utf-8", "replace")

    def close(self) -> str:
        time.sleep(0.5)  # what the child wrote last reaches the reader
        self.stop.set()
        self.reader.join(timeout=5.0)
        os.close(self.follower)
        os.close(self.leader)
        return self.text()


def _lines(text: str) -> list[str]:
    """The terminal's lines without the progress bar's redraws."""
    lines = [ln.split("\r")[-1].strip() for ln in text.replace("\r\n", "\n").splitlines()]
    return [ln for ln in lines if ln and not ln.startswith("baking [")]


@pytest.mark.parametrize("how", ["removed", "replaced by a file"])
def test_a_folder_taken_away_during_the_bake_is_one_sentence(tmp_path, how):
    """The folder goes while the tiles are evaluated: it used to end in `internal error: FileNotFoundError`
    (exit 3) once the last tile was done; now the bake stops at its next group of tiles."""
    env = _env(tmp_path)
    folder = tmp_path / "bakes"
    term = _Terminal()
    proc = _start(["bake", "--out", str(folder / "clouds.vdb"), "--voxel-size", "50"], env, stderr=term.follower)
    try:
        _wait_for(proc, lambda: re.search(r"baking \[#*\s*\]\s+[1-9]\d*\.\d%", term.text()))
        assert not re.search(r"100\.0%", term.text()), "the bake ended before its folder could be taken away"
        _take_away(folder, how)
        stdout, _ = proc.communicate(timeout=300)
    finally:
        text = term.close()
    assert proc.returncode == 1, text
    assert _lines(text) == [_sentence(folder, how)] and stdout == ""
    assert "Traceback" not in text and "internal error" not in text
    _left_as_taken(tmp_path, folder, how)


def test_a_folder_removed_while_the_vdb_is_written_is_one_sentence(tmp_path):
    """The folder goes inside the write itself (the run is frozen as soon as its staging folder appears):
    the writer's failure is said as the folder's, and no file is made again in its place."""
    env = _env(tmp_path)
    folder = tmp_path / "bakes"
    folder.mkdir()
    proc = _start(["bake", "--out", str(folder / "clouds.vdb"), "--voxel-size", "50"], env)
    _wait_for(proc, lambda: any(folder.glob(".nubis-tmp-*")))
    proc.send_signal(signal.SIGSTOP)
    try:
        shutil.rmtree(folder)
    finally:
        proc.send_signal(signal.SIGCONT)
    stdout, stderr = proc.communicate(timeout=300)
    assert proc.returncode == 1 and stderr.strip() == _sentence(folder, "removed") and stdout == "", stderr
    _left_as_taken(tmp_path, folder, "removed")


@pytest.mark.parametrize("how", ["removed", "replaced by a file", "moved away"])
def test_a_sequence_whose_folder_is_taken_away_is_one_sentence(tmp_path, how):
    """`bake --frames` stages every frame's file at its start: the folder goes after that, and no frame
    makes it (or its staging folder) again; a staging folder moved away with its folder is removed where
    it went."""
    env = _env(tmp_path)
    folder = tmp_path / "frames"
    folder.mkdir()
    args = ["bake", "--out", str(folder / "clouds_####.vdb"), "--voxel-size", "100", "--frames", "1-3"]
    proc = _start(args, env)
    _wait_for(proc, lambda: any(folder.glob(".nubis-tmp-*")))
    _take_away(folder, how)
    stdout, stderr = proc.communicate(timeout=300)
    lines = [ln for ln in stderr.splitlines() if ln.strip()]
    assert proc.returncode == 1 and lines[-1] == _sentence(folder, how) and stdout == "", stderr
    assert all(ln.startswith("nubis: ") for ln in lines) and "Traceback" not in stderr, stderr  # and the disk note
    _left_as_taken(tmp_path, folder, how)


def _entries(folder: Path) -> set[Path]:
    try:
        return set(folder.rglob("*"))
    except OSError:  # something went while it was listed: the run is there
        return {folder / "?"}


def test_a_failed_benchmark_vdb_leaves_nothing_of_its_own(tmp_path):
    """The VDB cloud goes after the cloudscape's stage started: the run fails at the second stage, and the
    first stage's files (out/cloudscape) used to stay. Now nothing of the run is left, and an earlier
    run's files are as they were."""
    env = _env(tmp_path)
    cloud = write_cumulus(tmp_path / "cumulus.vdb")
    out = tmp_path / "bench"
    (out / "cloudscape").mkdir(parents=True)
    earlier = {"notes.txt": b"the artist's notes", "cloudscape/benchmark.json": b'{"earlier": true}'}
    for name, data in earlier.items():
        (out / name).write_bytes(data)
    before = set(out.rglob("*"))
    args = ["benchmark", "--vdb", str(cloud), "--out", str(out), "--width", "32", "--height", "18"]
    proc = _start(args, env)
    _wait_for(proc, lambda: _entries(out) - before)  # the run has begun writing into `out`
    cloud.unlink()
    stdout, stderr = proc.communicate(timeout=600)
    assert proc.returncode == 1, stderr
    [line] = [ln for ln in stderr.splitlines() if ln.strip()]
    assert line.startswith("nubis: error: ") and "cumulus.vdb" in line and "Traceback" not in stderr
    assert stdout == ""
    assert set(out.rglob("*")) == before
    assert {name: (out / name).read_bytes() for name in earlier} == earlier
    assert list((tmp_path / "tmpdir").iterdir()) == []
