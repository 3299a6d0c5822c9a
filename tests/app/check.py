"""The verdict of the real-application stage: every step of the set that ran (both phases of
tests/app/session.py) ran and passed. A phase that crashed or timed out lacks steps, and fails here; a step
that ran but is not listed here fails too, so a new step is never left unjudged.

    python3 tests/app/check.py OUTDIR [--set full|quick]   the verdict (full by default)
    python3 tests/app/check.py --steps SET PHASE            the set's steps of a phase, comma-separated

The quick set (CI's, `tests/app/run --quick`) keeps what only the real application shows: the extension
built and installed by Blender's own tool, the clouds in a window's viewport, every sidebar panel drawn,
edits by clicks, F12 and Render Animation from the interface with an object in the clouds, Esc during an
animation, a bake, the file saved and reopened, and a farm's `blender -b -a`. It leaves out what the bpy
suite checks on every line (the viewport's grain at rest, the script and menu renders, VDB clouds, painting,
layered skies): the full set runs before each change lands (docs/measurements.md#ci).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

EXPECTED = {
    "main": [
        "startup",
        "install",
        "new_cloudscape",
        "grain",
        "sidebar",
        "edit",
        "render_eevee",
        "render_cycles",
        "peak",
        "peak_animation",
        "animation",
        "bake",
        "bake_disturbed",
        "render_clouds",
        "vdb_cloud",
        "paint",
        "layers",
        "save",
    ],
    "reopen": ["startup", "reopen", "farm"],
}
QUICK = {
    "main": ["startup", "install", "new_cloudscape", "sidebar", "edit", "peak", "peak_animation", "bake", "save"],
    "reopen": ["startup", "reopen", "farm"],
}
SETS = {"full": EXPECTED, "quick": QUICK}


def main(outdir: str, expected: dict[str, list[str]]) -> int:
    failed = 0
    for phase, steps in expected.items():
        path = Path(outdir) / f"results-{phase}.json"
        results = {r["step"]: r for r in json.loads(path.read_text())} if path.exists() else {}
        for name in steps:
            rec = results.get(name)
            if rec is None:
                print(f"FAIL {phase}/{name}: did not run (see console-{phase}.log)")
                failed += 1
                continue
            bad = [c["what"] for c in rec["checks"] if not c["ok"]]
            print(
                f"{'ok  ' if rec['ok'] else 'FAIL'} {phase}/{name} ({rec.get('seconds', '?')} s, "
                f"{len(rec['checks'])} checks)"
            )
            for what in bad:
                print(f"     - {what}")
            failed += not rec["ok"]
        for name in sorted(results.keys() - set(steps)):
            print(f"FAIL {phase}/{name}: ran but is not in check.py's EXPECTED (add it there so it is judged)")
            failed += 1
    print(f"real-application stage: {'passed' if not failed else f'{failed} step(s) failed'}")
    return 1 if failed else 0


if __name__ == "__main__":
    args = sys.argv[1:]
    if args[:1] == ["--steps"]:
        print(",".join(SETS[args[1]][args[2]]))
        sys.exit(0)
    which = args[args.index("--set") + 1] if "--set" in args else "full"
    sys.exit(main(args[0], SETS[which]))
