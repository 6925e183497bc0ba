"""Atomic file writing shared by the sinks: temporary name beside the target, then rename."""

from __future__ import annotations

import os
import uuid
from pathlib import Path


def temp_path_beside(path: Path) -> Path:
    """A fresh hidden temporary path in ``path``'s folder (same file system: rename is atomic).

    Unlike ``tempfile.mkstemp`` the file is not created here, so whoever
    writes it gets the usual permissions (umask), not 0600.
    """
    path = Path(path)
    return path.with_name(f".{path.name}.{os.getpid()}-{uuid.uuid4().hex[:12]}.tmp")


def remove_quietly(path: Path) -> None:
    try:
        Path(path).unlink()
    except FileNotFoundError:
        pass
