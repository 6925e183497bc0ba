"""The studies' grid cache (``OUT/cache/*.npz``) holds plain arrays only and never runs what a file holds.

A cache file is read with ``allow_pickle=False`` and checked against its key and the grid's shape: a file
planted in the cache folder (a pickle, an object array whose unpickling would run code, a foreign or
damaged file) is ignored with one line on stderr and the grid is simulated again; a valid one is read back.
"""

from __future__ import annotations

import pathlib
import pickle

import numpy as np
import pytest

from dicetrace.studies.context import Context, Options

WINDOW, RES = ((1.0, 1.2), (3.8, 4.0)), 3  # 9 throws


class _Touch:
    """Unpickling this creates ``marker``: the proof that a file's code ran."""

    def __init__(self, marker):
        self.marker = str(marker)

    def __reduce__(self):
        return (pathlib.Path.touch, (pathlib.Path(self.marker),))


def _fresh(tmp_path, **kw):
    ctx = Context("cache", Options(**kw), tmp_path / "cache")
    return ctx


def _only_cache_file(tmp_path) -> pathlib.Path:
    files = list((tmp_path / "cache").glob("*.npz"))
    assert len(files) == 1, files
    return files[0]


def test_a_valid_cache_is_read_back(tmp_path):
    ctx = _fresh(tmp_path)
    a = ctx.sample(WINDOW, RES)
    assert ctx.n_throws == 9
    path = _only_cache_file(tmp_path)
    with np.load(path, allow_pickle=False) as z:  # nothing in it needs pickle
        assert not any(z[k].dtype.hasobject for k in z.files)
    ctx2 = _fresh(tmp_path)
    b = ctx2.sample(WINDOW, RES)
    assert ctx2.n_throws == 0  # read back, not simulated
    assert (a.labels == b.labels).all() and np.array_equal(a.t_settle_s, b.t_settle_s, equal_nan=True)
    assert (a.status_code == b.status_code).all() and b.wall_s == pytest.approx(a.wall_s)
    assert all(np.array_equal(x, y) for x, y in zip(a.axes, b.axes)) and b.sequences is None


def test_contact_sequences_round_trip(tmp_path):
    ctx = _fresh(tmp_path)
    a = ctx.sample(WINDOW, RES, sequences=True)
    ctx2 = _fresh(tmp_path)
    b = ctx2.sample(WINDOW, RES, sequences=True)
    assert ctx2.n_throws == 0
    assert b.sequences.dtype == object and b.sequences.shape == a.sequences.shape
    assert b.sequences.tolist() == a.sequences.tolist() and all(isinstance(q, str) for q in b.sequences.ravel())


def _plant_object_npz(path, marker):
    """A .npz whose arrays hold objects: loading it with pickle allowed would create ``marker``."""
    evil = np.empty(1, dtype=object)
    evil[0] = _Touch(marker)
    with open(path, "wb") as f:
        np.savez(f, format=np.int64(2), key=evil, labels=evil, t_settle_s=evil, status_code=evil, wall_s=evil,
                 seq_bytes=evil, seq_offsets=evil, axis0=evil, axis1=evil)


def _plant_pickle(path, marker):
    path.write_bytes(pickle.dumps(_Touch(marker)))


def _plant_foreign_key(path, marker):
    """A well-formed cache file of another configuration (its grid would be wrong here)."""
    with np.load(path, allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    arrays["key"] = np.frombuffer(b'["another configuration"]', dtype=np.uint8)
    arrays["labels"] = np.full_like(arrays["labels"], 6)
    with open(path, "wb") as f:
        np.savez(f, **arrays)


def _plant_wrong_shape(path, marker):
    with np.load(path, allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    arrays["labels"] = arrays["labels"][:2]
    with open(path, "wb") as f:
        np.savez(f, **arrays)


def _plant_old_layout(path, marker):
    """A grid cached by an older dicetrace (no layout, no key): not trusted, simulated again."""
    with np.load(path, allow_pickle=False) as z:
        arrays = {k: z[k] for k in ("labels", "t_settle_s", "status_code", "wall_s", "axis0", "axis1")}
    with open(path, "wb") as f:
        np.savez(f, sequences=np.zeros(0), **arrays)


def _plant_garbage(path, marker):
    path.write_bytes(b"PK\x03\x04 not really a zip")


def _plant_truncated(path, marker):
    path.write_bytes(path.read_bytes()[:100])


@pytest.mark.parametrize("plant", [_plant_object_npz, _plant_pickle, _plant_foreign_key, _plant_wrong_shape,
                                   _plant_old_layout, _plant_garbage, _plant_truncated])
def test_a_planted_cache_file_never_runs_and_is_recomputed(tmp_path, capsys, plant):
    marker = tmp_path / "pwned"
    ctx = _fresh(tmp_path)
    good = ctx.sample(WINDOW, RES)
    path = _only_cache_file(tmp_path)
    plant(path, marker)
    capsys.readouterr()
    ctx2 = _fresh(tmp_path)
    got = ctx2.sample(WINDOW, RES)
    assert not marker.exists(), "a cache file ran code"
    assert ctx2.n_throws == 9  # simulated again, not read
    assert (got.labels == good.labels).all()
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and "cache file" in lines[0] and str(path) in lines[0] and "again" in lines[0], err
    # and the cache holds a good file again
    ctx3 = _fresh(tmp_path)
    ctx3.sample(WINDOW, RES)
    assert ctx3.n_throws == 0


def test_no_cache_ignores_the_files(tmp_path):
    _fresh(tmp_path).sample(WINDOW, RES)
    ctx = _fresh(tmp_path, no_cache=True)
    ctx.sample(WINDOW, RES)
    assert ctx.n_throws == 9


def test_a_folder_in_place_of_a_cache_file_is_left_alone(tmp_path, capsys):
    """A folder where the cache file goes: simulated again, the folder kept, one line each for read and write."""
    ctx = _fresh(tmp_path)
    good = ctx.sample(WINDOW, RES)
    path = _only_cache_file(tmp_path)
    path.unlink()
    path.mkdir()
    capsys.readouterr()
    ctx2 = _fresh(tmp_path)
    assert (ctx2.sample(WINDOW, RES).labels == good.labels).all() and ctx2.n_throws == 9
    assert path.is_dir() and not list((tmp_path / "cache").glob(".*tmp"))
    err = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    assert len(err) == 2 and "ignored (unreadable: Is a directory)" in err[0] and "cannot write cache file" in err[1], err
