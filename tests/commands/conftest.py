"""Fixtures of the hostile-input tests: a small full-able tmpfs (the folder snapshot is tests/conftest.py's)."""

from __future__ import annotations

import gc
import os
import subprocess
from pathlib import Path

import pytest


def _unmount(d: Path) -> None:
    """Unmount, retrying after a garbage collection (a handle still open), else detach lazily: never left mounted."""
    if subprocess.run(["umount", str(d)], capture_output=True).returncode != 0:
        gc.collect()
        if subprocess.run(["umount", str(d)], capture_output=True).returncode != 0:
            subprocess.run(["umount", "-l", str(d)], check=False, capture_output=True)


@pytest.fixture
def mount_small_tmpfs():
    """``mount_small_tmpfs(folder) -> bool``: mount a 64 KiB tmpfs there (root only; False when it cannot);
    every folder mounted is unmounted in teardown."""
    mounted: list[Path] = []

    def mount(d: Path) -> bool:
        if os.geteuid() != 0 or subprocess.run(["mount", "-t", "tmpfs", "-o", "size=64k", "tmpfs", str(d)],
                                               capture_output=True).returncode != 0:
            return False
        mounted.append(d)
        return True

    yield mount
    for d in mounted:
        _unmount(d)


@pytest.fixture
def tmpfs(tmp_path, mount_small_tmpfs):
    """A 64 KiB tmpfs folder (root only; unmounted in teardown)."""
    d = tmp_path / "small"
    d.mkdir()
    if not mount_small_tmpfs(d):
        pytest.skip("needs root to mount a small tmpfs (the injected-ENOSPC variants cover the rest)")
    return d


def _fill(folder: Path) -> None:
    """Fill ``folder``'s file system to the last byte."""
    with open(folder / "filler", "wb", buffering=0) as f:
        try:
            while True:
                f.write(b"\0" * 4096)
        except OSError:
            pass


@pytest.fixture
def fill_fs():
    """``fill_fs(folder)``: fill the folder's file system to the last byte (a file named ``filler``)."""
    return _fill
