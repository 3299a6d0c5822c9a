"""The presets the sidebar lists: the shipped ones, then the artist's own (Blender's extension user folder),
each parsed once per change of its file, a broken one listed as broken with its sentence."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from ...core import presets
from ...core.errors import NubisError
from . import runtime


@dataclass(frozen=True)
class PresetEntry:
    path: Path
    stem: str
    name: str
    description: str
    user: bool


_ENTRIES: dict = {}  # (folder listings and times) -> entries, parsed once per change of either folder


def preset_entries() -> list[PresetEntry]:
    """The shipped presets, then the user's own, each parsed once per change of its file."""
    folders = ((presets.preset_dir(), False), (runtime.user_preset_dir(), True))
    listing = [(user, sorted(f.glob("*.toml"))) for f, user in folders]
    key = tuple((p.name, p.stat().st_mtime_ns, user) for user, paths in listing for p in paths if p.is_file())
    if key not in _ENTRIES:
        entries = []
        for user, paths in listing:
            for path in paths:
                try:
                    preset = presets.load_preset(str(path))
                    entries.append(PresetEntry(path, path.stem, preset.name, preset.description or preset.name, user))
                except NubisError as err:
                    entries.append(PresetEntry(path, path.stem, f"{path.stem} (broken)", str(err), user))
        _ENTRIES.clear()
        _ENTRIES[key] = entries
    return _ENTRIES[key]


def active_preset(context) -> PresetEntry | None:
    """The preset the scene's cloudscape was last loaded from or saved as."""
    stem = context.scene.nubis.preset
    entries = preset_entries()
    # A user preset and a shipped one never share a stem (saving refuses shipped names).
    return next((e for e in entries if e.stem == stem and e.user), None) or next(
        (e for e in entries if e.stem == stem), None
    )


def find_preset_entry(stem: str) -> PresetEntry | None:
    return next((e for e in preset_entries() if e.stem == stem), None)
