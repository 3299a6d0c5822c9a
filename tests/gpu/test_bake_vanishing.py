"""A modal bake whose output folder goes while it runs, and a step that fails in a way nobody foresaw: the
operator says one sentence, the work is cleared (blender/jobs/work.py), and the next bake starts and succeeds.

In the interface a timer calls the operator's modal() once per group of tiles; background mode runs the
operators to their end at once, so here the operator's own modal() is called by hand with timer events, on
a stand-in that carries the real operator's jobs() and finished() (Bake VDB, Bake Sequence, Render Clouds).
"""

from __future__ import annotations

import shutil
from types import SimpleNamespace

import pytest

VOXEL = 100.0  # the default cloudscape in 36 tiles: five timer ticks of eight tiles per frame
TIMER = SimpleNamespace(type="TIMER")


def _driven(cls, **props):
    """The operator class `cls` as its timer drives it: its jobs, its finish and its modal(), its reports
    kept in `reports` (a bpy operator cannot be made without Blender running it)."""
    from nubis_addon.blender.jobs import work

    class Driven(work.ModalSteps):
        doing = cls.doing
        cancelled = cls.cancelled

        def __init__(self):
            self.__dict__.update(props)
            self.reports = []

        def jobs(self, context):
            return cls.jobs(self, context)

        def finished(self, context, results):
            return cls.finished(self, context, results)

        def report(self, kinds, text):
            self.reports.append((set(kinds), text))

    return Driven()


def _start(op, context):
    """What the operator's execute does in the interface, before Blender adds its modal handler."""
    from nubis_addon.blender.jobs import work

    op._work = work.Work(op.doing, list(op.jobs(context)))
    op.start(context)
    assert work.current() is op._work


def _tick_until(op, context, done, most: int = 500) -> set:
    """Timer ticks until done() holds (or the operator ends): the last modal() result."""
    for _ in range(most):
        result = op.modal(context, TIMER)
        if result != {"RUNNING_MODAL"} or done():
            return result
    raise AssertionError("the work never got there")


def _gone(folder) -> str:
    return (
        f"the output folder '{folder}' was removed while the bake ran: nothing was written; "
        "make the folder again and bake again"
    )


def test_bake_vdb_whose_folder_is_removed_says_so_and_the_next_bake_runs(blender, make_scene, tmp_path):
    from nubis_addon.blender.jobs import work
    from nubis_addon.blender.sidebar import operators

    make_scene("default")
    context = blender.context
    folder = tmp_path / "bakes"
    op = _driven(operators.NUBIS_OT_bake_vdb, filepath=str(folder / "clouds.vdb"), voxel_size=VOXEL)
    _start(op, context)
    assert op.modal(context, TIMER) == {"RUNNING_MODAL"} and op.reports == []  # 8 of 36 tiles
    assert folder.is_dir()  # the bake made it
    shutil.rmtree(folder)
    assert op.modal(context, TIMER) == {"CANCELLED"}
    assert op.reports == [({"ERROR"}, _gone(folder))]
    assert work.current() is None and op._work.done
    assert not folder.exists() and sorted(p.name for p in tmp_path.iterdir()) == []
    # The next bake is not refused, and writes its file.
    assert blender.ops.nubis.bake_vdb(filepath=str(folder / "clouds.vdb"), voxel_size=VOXEL) == {"FINISHED"}
    assert sorted(p.name for p in folder.iterdir()) == ["clouds.vdb"]


def test_bake_sequence_whose_folder_is_replaced_by_a_file_says_so_and_the_next_bake_runs(blender, make_scene, tmp_path):
    from nubis_addon.blender.jobs import work
    from nubis_addon.blender.sidebar import operators

    scene = make_scene("default")
    scene.frame_start, scene.frame_end = 1, 3
    scene.nubis.bake_voxel_size = VOXEL
    context = blender.context
    folder = tmp_path / "frames"
    op = _driven(operators.NUBIS_OT_bake_frames, directory=str(folder), step=1)
    _start(op, context)
    # The first frame is written, the second under way.
    _tick_until(op, context, lambda: len(op._work.results) == 1)
    assert op.modal(context, TIMER) == {"RUNNING_MODAL"} and op.reports == []
    assert sorted(p.name for p in folder.iterdir()) == ["clouds_0001.vdb"]
    shutil.rmtree(folder)
    folder.write_text("not a folder")
    assert op.modal(context, TIMER) == {"CANCELLED"}
    assert op.reports == [
        (
            {"ERROR"},
            f"the output folder '{folder}' was replaced by a file while the bake ran: nothing was written; "
            "move the file away, make the folder again and bake again",
        )
    ]
    assert work.current() is None and op._work.done
    assert folder.read_text() == "not a folder" and sorted(p.name for p in tmp_path.iterdir()) == ["frames"]
    folder.unlink()
    assert blender.ops.nubis.bake_frames(directory=str(folder), step=1) == {"FINISHED"}
    assert sorted(p.name for p in folder.iterdir()) == ["clouds_0001.vdb", "clouds_0002.vdb", "clouds_0003.vdb"]


@pytest.mark.parametrize("name", ["NUBIS_OT_bake_vdb", "NUBIS_OT_render_image"])
def test_an_unexpected_failure_of_a_step_is_said_and_clears_the_work(blender, make_scene, tmp_path, name):
    """A step raising anything at all (here a job that raises OSError half way) used to escape modal(): the
    work stayed registered and every later Bake or Render Clouds was refused."""
    from nubis_addon.blender.jobs import work
    from nubis_addon.blender.sidebar import operators

    make_scene("default")
    context = blender.context
    cls = getattr(operators, name)
    op = _driven(cls, filepath=str(tmp_path / "clouds.vdb"), voxel_size=VOXEL)
    real = cls.jobs(op, context)

    def failing(steps):
        yield next(steps)
        steps.close()
        raise OSError(5, "Input/output error")

    op.jobs = lambda _context: [(label, failing(steps)) for label, steps in real]
    _start(op, context)
    assert op.modal(context, TIMER) == {"RUNNING_MODAL"}
    assert op.modal(context, TIMER) == {"CANCELLED"}
    [(kinds, text)] = op.reports
    assert kinds == {"ERROR"} and text == (
        f"{cls.doing.capitalize()} stopped on an unexpected error (OSError: [Errno 5] Input/output error): "
        "see the system console for details, and report it"
    )
    assert work.current() is None
    assert sorted(tmp_path.iterdir()) == []
    assert blender.ops.nubis.bake_vdb(filepath=str(tmp_path / "clouds.vdb"), voxel_size=VOXEL) == {"FINISHED"}


def test_work_whose_operator_is_gone_is_cleared_when_the_next_starts(blender, make_scene, tmp_path):
    """Blender frees an operator whose modal() raised; its work, left registered, can step no more and took
    no Esc: the next bake clears it (nothing of it is written) instead of being refused."""
    from nubis_addon.blender.jobs import work

    scene = make_scene("default")
    kept = []

    class NUBIS_OT_test_gone(blender.types.Operator):
        bl_idname = "nubis.test_gone"
        bl_label = "An operator that ends at once"

        def execute(self, context):
            kept.append(self)
            return {"CANCELLED"}

    blender.utils.register_class(NUBIS_OT_test_gone)
    try:
        assert blender.ops.nubis.test_gone() == {"CANCELLED"}
    finally:
        blender.utils.unregister_class(NUBIS_OT_test_gone)
    ended = []
    running = work.start(work.Work("baking", work.bake_jobs(scene, str(tmp_path / "stale.vdb"), VOXEL, 1)))
    running.owner, running.on_cancel = kept[0], lambda: ended.append(True)
    running.step()
    assert blender.ops.nubis.bake_vdb(filepath=str(tmp_path / "next.vdb"), voxel_size=VOXEL) == {"FINISHED"}
    assert running.done and ended == [True] and work.current() is None
    assert sorted(p.name for p in tmp_path.iterdir()) == ["next.vdb"]
