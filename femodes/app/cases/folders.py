"""Application layer: the output folders of the commands (``--out``), created and checked writable."""

from __future__ import annotations

import sys
from pathlib import Path

__all__ = ["OutputFolderError", "usable_folder", "command_out_folder"]


class OutputFolderError(ValueError):
    """An output folder that cannot be used (a file in the way, no permission)."""


def usable_folder(folder: Path, option: str) -> Path:
    """Create ``folder`` (and parents) and check it is writable, or raise one-sentence
    :class:`OutputFolderError` naming ``option`` and what to change."""
    folder = Path(folder)
    blocker = next((p for p in (folder, *folder.parents) if p.exists() and not p.is_dir()), None)
    if blocker is not None:
        raise OutputFolderError(f"{option} {str(folder)!r}: {str(blocker)!r} is a file, not a folder; "
                                f"choose another {option}")
    try:
        folder.mkdir(parents=True, exist_ok=True)
        probe = folder / ".femodes-write-test"
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as exc:
        raise OutputFolderError(f"{option} {str(folder)!r} is not writable ({exc.strerror or exc}); "
                                f"choose another {option}") from None
    return folder


def command_out_folder(out: Path | None, default: Path, command: str) -> Path | None:
    """The ``--out`` folder of ``femodes COMMAND`` (``default`` if not given), created and
    writable; else None after printing the one-line error (the command then exits with 2)."""
    try:
        return usable_folder(out if out is not None else default, "--out")
    except OutputFolderError as exc:
        print(f"femodes {command}: {exc}", file=sys.stderr)
        return None
