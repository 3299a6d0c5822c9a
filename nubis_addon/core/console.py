"""The user's terminal, kept apart from Blender's chatter: the command line sends file descriptors 1
and 2 to a log while Blender works, so progress, warnings and the interrupt line are written to a
copy of the terminal's stderr made before that. No bpy here."""

from __future__ import annotations

import contextlib
import os
from collections.abc import Callable


class Console:
    def __init__(self) -> None:
        self.fd = os.dup(2)
        self.tty = os.isatty(self.fd)

    def write(self, text: str) -> None:
        with contextlib.suppress(OSError):
            os.write(self.fd, text.encode("utf-8", "replace"))

    def line(self, text: str) -> None:
        self.write(text.rstrip("\n") + "\n")

    def progress(self, label: str) -> Callable[[float], None] | None:
        """A progress bar on a terminal; nothing when stderr is a file or a pipe (logs stay clean)."""
        if not self.tty:
            return None

        def report(fraction: float) -> None:
            fraction = min(max(fraction, 0.0), 1.0)
            bar = "#" * int(fraction * 30)
            self.write(f"\r{label} [{bar:<30}] {fraction * 100:5.1f}%" + ("\n" if fraction >= 1.0 else ""))

        return report

    def close(self) -> None:
        with contextlib.suppress(OSError):
            os.close(self.fd)
