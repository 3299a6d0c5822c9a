"""The verdict of the real-application stage: every step of both phases of tests/app/session.py ran and
passed. A phase that crashed or timed out lacks steps, and fails here; a step that ran but is not listed
here fails too, so a new step is never left unjudged.

    python3 tests/app/check.py OUTDIR
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


def main(outdir: str) -> int:
    failed = 0
    for phase, steps in EXPECTED.items():
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
    sys.exit(main(sys.argv[1]))
