"""`python -m nubis_addon ...`: Blender as a Python module, in background mode."""

import os
import sys

from .cli import main

if __name__ == "__main__":
    code = main()
    sys.stdout.flush()
    sys.stderr.flush()
    # Skip interpreter teardown: nanobind's "leaked instance" notices from Blender's bundled OpenVDB and
    # OpenImageIO would otherwise follow the summary line (PLATFORM.md). Files are all closed by now.
    os._exit(code)
