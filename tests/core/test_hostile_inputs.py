"""What a hostile but realistic user does, answered in core/ alone (no Blender, milliseconds to a second):
voxel sizes suggested by a refused bake, a sequence larger than the disk, litter of killed runs, a folder
where an output goes, names no file can have."""

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from nubis_addon.core import bakeplan, fields, interrupt, sequence, staging
from nubis_addon.core.bakeplan import BakePlan, Tile, plan_bake
from nubis_addon.core.errors import NubisError
from nubis_addon.core.fsutil import check_output_path, not_a_file
from nubis_addon.core.presets import find_preset, load_preset
from nubis_addon.core.state import CloudState


def _state(**params) -> CloudState:
    preset = load_preset("default")
    p = dict(preset.params, field_resolution=64, **params)
    f = fields.composite(preset.layers, p)
    return CloudState(params=p, field_a=f["a"], field_b=f["b"], field_c=f["cirrus"])


@pytest.mark.parametrize(
    ("params", "voxel"),
    [
        ({}, 1.0),  # a box of too many tiles: the coarse bound
        ({"layer_draw_radius": 500_000.0, "field_size": 1_000_000.0}, 150.0),  # the memory estimate
    ],
)
def test_a_refused_bake_names_the_smallest_voxel_size_that_then_fits(params, voxel):
    """The size was scaled from the estimate as if memory fell with the cube of the voxel size; the tiles'
    margins make it fall slower, so the size named was refused in turn (500 km draw radius: 150 m said
    "at least 194 m", 194 m said "at least 206 m"; the default sky at 1 m said 17 m, 17 m said 24 m)."""
    state = _state(**params)
    with pytest.raises(NubisError, match=r"use a voxel size of at least [\d.]+ m$") as err:
        plan_bake(state, voxel)
    suggested = float(re.search(r"at least ([\d.]+) m", str(err.value)).group(1))
    plan_bake(state, suggested)  # fits: no error
    below = suggested - 10.0 ** (len(str(int(suggested))) - 3)  # one step of its three figures down
    with pytest.raises(bakeplan.BakeTooLarge):
        plan_bake(state, below)
    assert err.value.suggested == suggested


def test_a_sequence_larger_than_the_free_disk_is_refused_with_how_many_frames_fit(tmp_path):
    """`bake --frames 1-100000` baked frame after frame with no estimate until the disk ran out."""
    plan = BakePlan((0.0, 0.0, 0.0), 100.0, (256, 256, 40), tiles=(Tile(0, 0, 128, 128, ((0, 40),)),))
    full, half = plan.file_bytes_estimate(), plan.file_bytes_estimate(half=True)
    assert full > half > 128 * 128 * 40 // 2
    velocity = BakePlan(plan.origin, 100.0, plan.dims, tiles=plan.tiles, velocity=True)
    assert velocity.file_bytes_estimate() > 3 * full
    frames = sequence.parse_frames("1-100000")
    pattern = tmp_path / "c_####.vdb"
    with pytest.raises(NubisError) as err:
        sequence.check_disk_space(pattern, frames, 1_000_000, free=250_000_000)
    assert str(err.value) == (
        f"--frames 1-100000 would write 100000 files of up to 1.0 MB each, up to 100.0 GB, but '{tmp_path}' has "
        "250.0 MB free: bake at most 250 frames at a time (--frames 1-250), or bake coarser voxels "
        "(--voxel-size) or half floats (--half)"
    )
    with pytest.raises(NubisError, match=r"has 500 bytes free: free some space, or bake coarser voxels \(--voxel"):
        sequence.check_disk_space(pattern, frames, 1_000_000, half=True, free=500)
    line = sequence.check_disk_space(pattern, frames[:24], 1_000_000)  # the real free space of tmp_path
    assert line.startswith("nubis: 24 frames of up to 1.0 MB each, up to 24.0 MB of the ") and str(tmp_path) in line


def test_the_litter_of_killed_runs_is_swept_and_nothing_else(tmp_path):
    """After a SIGKILL, blender_XXXXXX and nubis-*.log stayed in the temporary folder for good."""
    dead = int(subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True).stdout)
    host, me = interrupt.HOST, os.getpid()
    made = {
        f"nubis-log-{host}-{dead}-abcd1234.log": False,  # False: a file
        f"nubis-world-{host}-{dead}-abcd1234": True,
        f"nubis-cycles-{host}-{dead}-abcd1234": True,
        f"nubis-log-{host}-{me}-abcd1234.log": False,  # a run still going
        f"nubis-world-other_machine-{dead}-abcd1234": True,  # a shared folder: another machine's run
        "nubis-abcd1234.log": False,  # a log kept for an internal fault, named in its message
        "blender_dead01": True,
        "blender_live01": True,
        "blender_user01": True,  # someone's Blender, not ours
        "notes.txt": False,
    }
    for name, folder in made.items():
        (tmp_path / name).mkdir() if folder else (tmp_path / name).write_text("x")
    (tmp_path / "blender_dead01" / f".nubis-{host}-{dead}").touch()
    (tmp_path / "blender_live01" / f".nubis-{host}-{me}").touch()
    interrupt.sweep_temp(tmp_path)
    gone = {f"nubis-log-{host}-{dead}-abcd1234.log", f"nubis-world-{host}-{dead}-abcd1234"}
    gone |= {f"nubis-cycles-{host}-{dead}-abcd1234", "blender_dead01"}
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(set(made) - gone)
    assert interrupt.owned_prefix("log") == f"nubis-log-{host}-{me}-"
    with interrupt.temporary_dir("nubis-world-") as made_now:
        assert Path(made_now).name.startswith(f"nubis-world-{host}-{me}-")


def test_a_folder_under_an_output_name_stops_the_set_before_the_first_rename(tmp_path):
    """compare into a folder whose metrics.json is a folder replaced seven files, then failed on the eighth
    with an internal IsADirectoryError: a mixed set. Every target is checked before anything moves."""
    for name in ("a.txt", "b.txt"):
        (tmp_path / name).write_text(f"old {name}")
    message = f"cannot write '{tmp_path / 'c.txt'}': a folder has that name, move or remove it, or choose another"
    with pytest.raises(NubisError, match=re.escape(message)), staging.output_set() as outputs:
        for name in ("a.txt", "b.txt", "c.txt"):
            outputs.stage(tmp_path / name).write_text("new")
        (tmp_path / "c.txt").mkdir()  # appears while the set is made
    assert [(tmp_path / n).read_text() for n in ("a.txt", "b.txt")] == ["old a.txt", "old b.txt"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.txt", "b.txt", "c.txt"]
    with pytest.raises(NubisError, match=re.escape(message)), staging.output_set() as outputs:
        outputs.stage(tmp_path / "c.txt")  # there before: said at once, before any work


def test_a_folder_moved_the_instant_its_staging_folder_appears_leaves_nothing_where_it_went(tmp_path, monkeypatch):
    """`mv frames elsewhere` between the staging folder's making and its opening left the staging folder in
    `elsewhere` (CI, loaded machine: bake --frames, the move the instant `.nubis-tmp-*` appeared): it is now
    made and opened through a descriptor of its output folder, so the run still holds it where it went."""
    folder, elsewhere = tmp_path / "frames", tmp_path / "elsewhere"
    folder.mkdir()
    made = staging._new_folder

    def made_then_moved(parent):
        name = made(parent)
        folder.rename(elsewhere)  # the user's mv, between the mkdir and the open
        return name

    monkeypatch.setattr(staging, "_new_folder", made_then_moved)
    with pytest.raises(staging.FolderGone, match="was removed"), staging.output_set() as outputs:
        outputs.stage(folder / "clouds_0001.vdb")
        assert len(list(elsewhere.iterdir())) == 1
        outputs.check()
    assert list(elsewhere.iterdir()) == []


def test_names_no_file_can_have_are_said_not_raised(tmp_path):
    """An image layer's path with a NUL (a TOML string can hold one) was `internal error: ValueError`;
    a --preset path with a 300-byte folder name `internal error: OSError: [Errno 36]`; a non-UTF-8 --out
    rendered for 20 s, then failed in OpenImageIO with a multi-line TypeError."""
    assert not_a_file(Path("evil\x1b[2J\x00x.png")) == (
        "has a NUL character (\\x00) in its name, which no file name can hold"
    )
    with pytest.raises(NubisError, match="the preset file '.*' has a name longer than the file system allows: give"):
        find_preset(f"/tmp/{'c' * 300}/x.toml")
    with pytest.raises(NubisError, match="no preset named 'c{300}': choose one of"):
        find_preset("c" * 300)
    with pytest.raises(NubisError, match="the preset file '.*' is a folder, not a file: give the path of a .toml"):
        find_preset(str(tmp_path) + os.sep)
    with pytest.raises(NubisError, match="preset file '/dev/zero' is a device or special file, not a regular file"):
        find_preset("/dev/zero")
    with pytest.raises(NubisError, match=r"the output '.*/x\\xff\.png' is not valid UTF-8: the image and volume"):
        check_output_path(os.fsdecode(os.fsencode(str(tmp_path)) + b"/x\xff.png"), (".png",))


def test_a_measured_active_share_lets_a_bake_the_bound_refuses_fit_and_nothing_else_does():
    """The bound counts every evaluated voxel as cloud; a probe's measured share (with its margin) plans
    by what the clouds fill. The share scales the estimate, never lets the box alone or nonsense through."""
    state = _state(layer_draw_radius=500_000.0, field_size=1_000_000.0)
    with pytest.raises(bakeplan.BakeTooLarge) as refused:
        plan_bake(state, 150.0)
    bound = plan_bake(state, refused.value.suggested)
    share = bakeplan.measured_share(active=bound.evaluated_voxels // 20, evaluated=bound.evaluated_voxels)
    assert share == pytest.approx(0.05 * bakeplan.SHARE_MARGIN, rel=1e-6)
    shared = plan_bake(state, refused.value.suggested, active_share=share)
    assert shared.evaluated_voxels == bound.evaluated_voxels
    assert shared.bytes_estimate - bakeplan.BASE_BYTES == pytest.approx(
        (bound.bytes_estimate - bakeplan.BASE_BYTES) * share, rel=1e-6
    )
    finer = plan_bake(state, 150.0, active_share=share)  # refused by the bound, fits by the share
    assert finer.active_share == share and finer.bytes_estimate <= bakeplan.DEFAULT_MEMORY_LIMIT
    with pytest.raises(bakeplan.BakeTooLarge):  # a share cannot make an absurd size fit
        plan_bake(state, 20.0, active_share=share)
    assert bakeplan.measured_share(0, 1000) == bakeplan.SHARE_FLOOR
    assert bakeplan.measured_share(900, 1000) == 1.0
    assert bakeplan.measured_share(5, 0) == 1.0
    for bad in (0.0, -0.1, 1.5, float("nan")):
        with pytest.raises(NubisError, match="active share"):
            plan_bake(state, 500.0, active_share=bad)
