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


def quaternions_xyzw(trace):
    """Unit orientation quaternions (n, 4), x y z w, world from body, from a trace's node offsets.

    Rows where the state is not finite (a numerical failure) are NaN instead of raising.
    """
    import numpy as np

    rot = trace.rotation
    q = np.full((len(rot), 4), np.nan)
    ok = np.isfinite(rot).all(axis=(1, 2)) & written_rows(trace)
    if ok.any():
        from scipy.spatial.transform import Rotation

        q[ok] = Rotation.from_matrix(rot[ok]).as_quat()
    return q


def written_rows(trace):
    """Boolean mask of the trace rows that hold a state.

    A run that ends in a numerical failure (blow_up, non_finite) may leave its
    last row unwritten (all zeros): no real state has all eight node offsets
    zero, so such rows are masked out.
    """

    return ~(trace.node_offsets == 0.0).all(axis=(1, 2))
