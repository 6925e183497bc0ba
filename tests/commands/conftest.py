"""Fixtures of the hostile-input tests: a byte-for-byte snapshot of a folder, and a small full-able tmpfs."""

from __future__ import annotations

import gc
import os
import stat
import subprocess
from pathlib import Path

import pytest


def _snapshot(root: Path) -> dict:
    """Everything under ``root``: type, bytes, mode and link target of each entry (symlinks not followed)."""
    out = {}
    for dirpath, dirnames, filenames in os.walk(root, followlinks=False):
        for name in dirnames + filenames:
            p = Path(dirpath) / name
            st_ = p.lstat()
            rel = str(p.relative_to(root))
            if stat.S_ISLNK(st_.st_mode):
                out[rel] = ("link", os.readlink(p))
            elif stat.S_ISDIR(st_.st_mode):
                out[rel] = ("dir", stat.S_IMODE(st_.st_mode))
            elif stat.S_ISREG(st_.st_mode):
                out[rel] = ("file", p.read_bytes(), stat.S_IMODE(st_.st_mode))
            else:
                out[rel] = ("special", stat.S_IFMT(st_.st_mode), st_.st_rdev)
    return out


@pytest.fixture
def snapshot():
    """``snapshot(folder)``: a dict of every entry's type, bytes, mode and link target, to compare before and after."""
    return _snapshot


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
