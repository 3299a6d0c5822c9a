"""`python -m nubis_addon ...`: Blender as a Python module, in background mode."""

import os
import shutil
import sys

from .cli import main
from .core.interrupt import blender_tempdir

if __name__ == "__main__":
    code = main()
    sys.stdout.flush()
    sys.stderr.flush()
    # Blender's session folder is removed by Blender's teardown, which is skipped below.
    tmp = blender_tempdir()
    if tmp is not None:
        shutil.rmtree(tmp, ignore_errors=True)
    # Skip interpreter teardown: nanobind's "leaked instance" notices from Blender's bundled OpenVDB and
    # OpenImageIO would otherwise follow the summary line (docs/platform-notes.md#nanobind-leak-notices).
    # Files are all closed by now.
    os._exit(code)
