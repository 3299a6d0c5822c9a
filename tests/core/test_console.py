"""The terminal's progress bar and the interrupt line (core/console.py), written from two threads."""

import os
import threading
import time

from nubis_addon.core import console


def _terminal(tmp_path):
    term = console.Console()
    os.close(term.fd)
    term.fd = os.open(tmp_path / "terminal", os.O_WRONLY | os.O_CREAT)
    term.tty = True  # as on a terminal: the bar is drawn
    return term


def test_the_last_words_end_the_bar_and_nothing_is_written_after_them(tmp_path):
    """The signal watcher writes the interrupt line while the main thread draws the bar: the line was once
    appended to a bar's line and followed by a later bar (Blender 4.5, CI)."""
    term = _terminal(tmp_path)
    bar = term.progress("rendering")
    bar(0.031)
    later = threading.Thread(target=bar, args=(0.032,), daemon=True)
    try:
        console.last_words(term.fd, "nubis: interrupted\n")
        later.start()
        later.join(timeout=0.5)
        assert later.is_alive(), "a bar drawn after the last words went through"
        text = (tmp_path / "terminal").read_text()
        assert text.endswith("]   3.1%\nnubis: interrupted\n"), repr(text)
    finally:
        console._lock.release()  # the process goes on here (an interrupt would have ended it)
        later.join(timeout=5.0)
        term.close()
    assert not later.is_alive()


def test_a_bar_and_lines_from_two_threads_never_share_a_line(tmp_path):
    term = _terminal(tmp_path)
    bar = term.progress("baking")
    stop = time.monotonic() + 0.3

    def draw():
        i = 0
        while time.monotonic() < stop:
            bar((i % 999) / 1000)
            i += 1

    threads = [threading.Thread(target=draw) for _ in range(2)]
    for t in threads:
        t.start()
    n = 0
    while time.monotonic() < stop:
        term.line(f"note {n}")
        n += 1
    for t in threads:
        t.join()
    term.close()
    parts = (tmp_path / "terminal").read_text().replace("\r", "\n").split("\n")
    notes = [p for p in parts if "note" in p]
    assert len(notes) == n and all(p.startswith("note ") for p in notes), notes[:5]
