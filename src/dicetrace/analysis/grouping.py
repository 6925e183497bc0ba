"""Group rolls into basins and count them.

A *grouping config* turns a rolls table (one row per initial condition, see
the ``rolls`` table of ``dicetrace.tables``) into one hashable label per row, in the manner of
Attractors.jl's ``group_features(features, config) -> labels``. The labels are
what every other analysis function works on: outcome grids, basin fractions,
cells, boundaries.

Two configs exist:

- :class:`GroupByOutcome`: the face that ends up on top (1..6), 0 for
  "undefined" (the top four nodes are no face) and -1 for "did not settle".
- :class:`GroupByContactSequence`: the ground-contact set sequence (writeup
  section 5.5), optionally reduced modulo the cube's 24 rotations or 48
  symmetries.

Contact sets are 8-bit masks, bit ``n - 1`` set when node ``n`` is on or below
the ground; node ``n = 1 + 4*[x>0] + 2*[y>0] + [z>0]`` in body coordinates.
"""

from __future__ import annotations

import abc
import dataclasses
import itertools
from collections.abc import Hashable, Iterable, Sequence
from functools import lru_cache
from typing import Literal

import numpy as np

from dicetrace.body import NODE_SIGNS
import pandas as pd
from scipy import stats

__all__ = [
    "AbstractGroupingConfig",
    "GroupByOutcome",
    "GroupByContactSequence",
    "group_features",
    "basins_fractions",
    "basins_fractions_table",
    "wilson_interval",
    "cube_node_permutations",
    "contact_sequence_text",
    "parse_contact_sequence",
    "permute_contact_sets",
    "canonical_contact_sequence",
    "UNSETTLED_LABEL",
    "UNDEFINED_LABEL",
]

#: Label of an initial condition whose roll did not settle (time cap, blow-up).
UNSETTLED_LABEL = -1
#: Label of a settled roll whose top four nodes are no face.
UNDEFINED_LABEL = 0

# --------------------------------------------------------------------------
# Cube symmetries acting on node numbers
# --------------------------------------------------------------------------


def _node_coords() -> np.ndarray:
    """Body coordinates (8, 3) of nodes 1..8 (row n-1), entries +-1 (``dicetrace.body.NODE_SIGNS``)."""
    return NODE_SIGNS.astype(int)


def _node_index(coords: np.ndarray) -> np.ndarray:
    """0-based node index of body coordinates (..., 3) with entries +-1."""
    c = np.asarray(coords) > 0
    return 4 * c[..., 0] + 2 * c[..., 1] + c[..., 2]


@lru_cache(maxsize=2)
def _perm_table(reflections: bool) -> np.ndarray:
    coords = _node_coords()
    perms = []
    for axes in itertools.permutations(range(3)):
        for signs in itertools.product((1, -1), repeat=3):
            m = np.zeros((3, 3), dtype=int)
            for r, (a, s) in enumerate(zip(axes, signs)):
                m[r, a] = s
            if not reflections and round(np.linalg.det(m)) != 1:
                continue
            perms.append(_node_index(coords @ m.T))
    table = np.array(perms, dtype=np.int64)
    # identity first, then a fixed (lexicographic) order
    order = sorted(range(len(table)), key=lambda q: tuple(table[q]))
    table = table[order]
    table.setflags(write=False)
    return table


def cube_node_permutations(*, reflections: bool = False) -> np.ndarray:
    """Node permutations induced by the symmetries of the cube.

    Parameters
    ----------
    reflections : bool, optional
        ``False`` (default): the 24 proper rotations. ``True``: all 48
        symmetries (rotations and rotation-reflections).

    Returns
    -------
    numpy.ndarray of int64, shape (24, 8) or (48, 8)
        Row ``q`` maps the 0-based node index ``n`` to ``perm[q, n]``. Row 0 is
        the identity. Read-only.

    Notes
    -----
    Each symmetry is a signed 3x3 permutation matrix acting on the body
    coordinates of the nodes, whose entries are +-1 (docs/model.md §3).
    """
    return _perm_table(bool(reflections))


def _sets_to_array(sets) -> np.ndarray:
    arr = np.asarray(list(sets) if not isinstance(sets, np.ndarray) else sets)
    if arr.size == 0:
        return np.zeros(0, dtype=np.uint8)
    return arr.astype(np.uint8, copy=False).ravel()


def contact_sequence_text(sets: Iterable[int]) -> str:
    """Text form of a contact-set sequence, in the seed program's format.

    Parameters
    ----------
    sets : iterable of int
        8-bit node masks (bit ``n - 1`` = node ``n`` on/below the ground).

    Returns
    -------
    str
        Each set written as its node numbers ascending (``0`` for the empty
        set), joined by ``-``; e.g. ``[0, 32, 40, 128, 0, 4]`` ->
        ``"0-6-68-8-0-3"``.
    """
    from dicetrace.simulate import sets_to_text  # lazy: numba, through dicetrace.simulate; dicetrace.analysis has none

    return sets_to_text(_sets_to_array(sets))


def parse_contact_sequence(text: str) -> np.ndarray:
    """Parse the text form back into 8-bit node masks.

    Parameters
    ----------
    text : str
        E.g. ``"0-6-68-8-0-3"``. The empty string gives an empty sequence.

    Returns
    -------
    numpy.ndarray of uint8
    """
    from dicetrace.simulate import text_to_sets  # lazy: numba, through dicetrace.simulate; dicetrace.analysis has none

    if text == "":
        return np.zeros(0, dtype=np.uint8)
    return text_to_sets(text)


@lru_cache(maxsize=4)
def _mask_tables(reflections: bool) -> np.ndarray:
    """(nsym, 256) table: mask -> permuted mask."""
    perms = cube_node_permutations(reflections=reflections)
    masks = np.arange(256)
    out = np.zeros((len(perms), 256), dtype=np.uint8)
    for q, p in enumerate(perms):
        acc = np.zeros(256, dtype=np.int64)
        for n in range(8):
            acc |= ((masks >> n) & 1) << p[n]
        out[q] = acc
    out.setflags(write=False)
    return out


def permute_contact_sets(sets, perm: Sequence[int]) -> np.ndarray:
    """Apply a node permutation to every set of a sequence.

    Parameters
    ----------
    sets : array_like of uint8
        Node masks.
    perm : sequence of 8 int
        0-based node map, e.g. a row of :func:`cube_node_permutations`.

    Returns
    -------
    numpy.ndarray of uint8
    """
    arr = _sets_to_array(sets).astype(np.int64)
    out = np.zeros_like(arr)
    for n in range(8):
        out |= ((arr >> n) & 1) << int(perm[n])
    return out.astype(np.uint8)


_Canonical = Literal[None, "rotations", "symmetries"]


def canonical_contact_sequence(seq, *, canonical: _Canonical = "rotations") -> str:
    """Canonical text of a contact sequence modulo cube symmetries.

    Parameters
    ----------
    seq : str or array_like of uint8
        Text form (``"0-6-68-8"``) or node masks.
    canonical : {None, "rotations", "symmetries"}, optional
        ``None``: the sequence's own text. ``"rotations"`` (default): modulo the
        24 rotations of the cube. ``"symmetries"``: modulo all 48 symmetries
        (rotations and reflections).

    Returns
    -------
    str
        The lexicographically smallest text (Python ``str`` order) among the
        images of the sequence under the group; each symmetry is applied to
        every set of the sequence.

    Notes
    -----
    The ground breaks the cube's symmetry: only the rotations that keep the
    vertical fixed are symmetries of a roll. Reducing modulo the whole group
    compares the *shape* of the contact history (which corners, in which
    pattern) regardless of which numbered corners played the roles.
    """
    sets = parse_contact_sequence(seq) if isinstance(seq, str) else _sets_to_array(seq)
    if canonical is None:
        return contact_sequence_text(sets)
    if canonical not in ("rotations", "symmetries"):
        raise ValueError(f"canonical must be None, 'rotations' or 'symmetries', not {canonical!r}")
    table = _mask_tables(canonical == "symmetries")
    images = table[:, sets]  # (nsym, len)
    return min(contact_sequence_text(row) for row in images)


# --------------------------------------------------------------------------
# Grouping configs
# --------------------------------------------------------------------------


class AbstractGroupingConfig(abc.ABC):
    """Base of the grouping configs used by :func:`group_features`.

    For developers
    --------------
    A subclass is a frozen dataclass that implements
    ``group(df: pandas.DataFrame) -> pandas.Series`` returning one hashable
    label (``int``, ``str`` or ``tuple``) per row, indexed like ``df``.
    """

    @abc.abstractmethod
    def group(self, df: pd.DataFrame) -> pd.Series:  # pragma: no cover - interface
        raise NotImplementedError


def _settled_mask(df: pd.DataFrame) -> np.ndarray:
    if "status" not in df.columns:
        return np.ones(len(df), dtype=bool)
    return (df["status"].astype(str) == "settled").to_numpy()


@dataclasses.dataclass(frozen=True)
class GroupByOutcome(AbstractGroupingConfig):
    """Label each roll by its outcome face.

    Parameters
    ----------
    mark_unsettled : bool, optional
        If ``True`` (default), rows whose ``status`` is not ``"settled"`` get
        label ``-1`` whatever their ``outcome`` column says.
    column : str, optional
        Outcome column, default ``"outcome"`` (1..6, 0 undefined).

    Labels are ``int``: 1..6 faces, 0 undefined, -1 did not settle.
    """

    mark_unsettled: bool = True
    column: str = "outcome"

    def group(self, df: pd.DataFrame) -> pd.Series:
        labels = df[self.column].to_numpy().astype(np.int64)
        if self.mark_unsettled:
            labels = np.where(_settled_mask(df), labels, UNSETTLED_LABEL)
        return pd.Series(labels, index=df.index, name="label", dtype=np.int64)


@dataclasses.dataclass(frozen=True)
class GroupByContactSequence(AbstractGroupingConfig):
    """Label each roll by its ground-contact set sequence.

    Two rolls are "topologically the same" (writeup section 5.5) when the
    sequences are equal.

    Parameters
    ----------
    canonical : {None, "rotations", "symmetries"}, optional
        Reduce each sequence modulo the cube's 24 rotations or 48 symmetries
        (see :func:`canonical_contact_sequence`). Default ``None``.
    mark_unsettled : bool, optional
        If ``True``, unsettled rows get the label ``"-1"``. Default ``False``
        (the sequence up to the time cap is kept).
    column : str, optional
        Text column, default ``"contact_sequence"``. When it is missing, the
        ``contact_sets`` column (lists or arrays of uint8 masks) is used.

    Labels are ``str``.
    """

    canonical: _Canonical = None
    mark_unsettled: bool = False
    column: str = "contact_sequence"

    def __post_init__(self):
        if self.canonical not in (None, "rotations", "symmetries"):
            raise ValueError(
                f"canonical must be None, 'rotations' or 'symmetries', not {self.canonical!r}"
            )

    def group(self, df: pd.DataFrame) -> pd.Series:
        if self.column in df.columns:
            texts = [str(t) for t in df[self.column].tolist()]
        elif "contact_sets" in df.columns:
            texts = [contact_sequence_text(s) for s in df["contact_sets"].tolist()]
        else:
            raise KeyError(f"rolls table has neither {self.column!r} nor 'contact_sets'")
        if self.canonical is not None:
            cache: dict[str, str] = {}
            out = []
            for t in texts:
                c = cache.get(t)
                if c is None:
                    c = cache[t] = canonical_contact_sequence(t, canonical=self.canonical)
                out.append(c)
            texts = out
        labels = np.array(texts, dtype=object)
        if self.mark_unsettled:
            labels[~_settled_mask(df)] = str(UNSETTLED_LABEL)
        return pd.Series(labels, index=df.index, name="label", dtype=object)


def group_features(df: pd.DataFrame, config: AbstractGroupingConfig) -> pd.Series:
    """Label every roll of a rolls table according to a grouping config.

    Parameters
    ----------
    df : pandas.DataFrame
        Rolls table (the ``rolls`` table of ``dicetrace.tables``).
    config : AbstractGroupingConfig
        E.g. ``GroupByOutcome()`` or ``GroupByContactSequence(canonical="rotations")``.

    Returns
    -------
    pandas.Series
        One hashable label per row, indexed like ``df``, named ``"label"``.

    Notes
    -----
    Modelled on Attractors.jl ``group_features(features, config)``.
    """
    if not isinstance(config, AbstractGroupingConfig):
        raise TypeError(f"config must be a grouping config, not {type(config).__name__}")
    return config.group(df)


# --------------------------------------------------------------------------
# Fractions
# --------------------------------------------------------------------------


def _sort_key(v):
    if isinstance(v, (int, np.integer)):
        return (0, int(v), "")
    if isinstance(v, (float, np.floating)):
        return (0, float(v), "")
    return (1, 0, str(v))


def _label_counts(labels, exclude: Iterable[Hashable]) -> tuple[list, np.ndarray]:
    if isinstance(labels, pd.Series):
        values = labels.to_numpy()
    else:
        values = np.asarray(labels)
    values = values.ravel()
    if values.dtype == object or values.dtype.kind in "UST":
        ser = pd.Series(values, dtype=object)
        vc = ser.value_counts(sort=False, dropna=False)
        keys, counts = list(vc.index), vc.to_numpy()
    else:
        u, c = np.unique(values, return_counts=True)
        keys, counts = [k.item() for k in u], c
    excl = set(exclude)
    pairs = [(k, int(c)) for k, c in zip(keys, counts) if k not in excl]
    pairs.sort(key=lambda kc: _sort_key(kc[0]))
    return [k for k, _ in pairs], np.array([c for _, c in pairs], dtype=np.int64)


def basins_fractions(labels, *, exclude: Iterable[Hashable] = ()) -> dict:
    """Fraction of initial conditions carrying each label.

    Parameters
    ----------
    labels : array_like or pandas.Series
        Labels of any shape (e.g. a label grid or the output of
        :func:`group_features`).
    exclude : iterable, optional
        Labels left out of both numerator and denominator (e.g. ``(0, -1)``).
        By default 0 and -1 are labels like any other.

    Returns
    -------
    dict
        label -> fraction; the fractions sum to 1 (empty dict for no labels).

    Notes
    -----
    Named after Attractors.jl ``basins_fractions``.
    """
    keys, counts = _label_counts(labels, exclude)
    n = counts.sum()
    if n == 0:
        return {}
    return {k: c / n for k, c in zip(keys, counts)}


def wilson_interval(count, n, *, confidence: float = 0.95):
    """Wilson score interval of a binomial proportion.

    Parameters
    ----------
    count, n : int or array_like of int
        Successes and trials (``n > 0``).
    confidence : float, optional
        Two-sided coverage, default 0.95.

    Returns
    -------
    (ci_low, ci_high) : tuple of float or numpy.ndarray

    Notes
    -----
    Wilson (1927), J. Am. Stat. Assoc. 22:209; recommended by Newcombe (1998),
    Stat. Med. 17:857 (method 3). With ``z`` the normal quantile,
    ``centre = (p + z^2/2n) / (1 + z^2/n)`` and
    ``half = z sqrt(p(1-p)/n + z^2/4n^2) / (1 + z^2/n)``.
    """
    count = np.asarray(count, dtype=float)
    n = np.asarray(n, dtype=float)
    z = stats.norm.ppf(0.5 + confidence / 2)
    p = count / n
    denom = 1 + z**2 / n
    centre = (p + z**2 / (2 * n)) / denom
    half = z * np.sqrt(p * (1 - p) / n + z**2 / (4 * n**2)) / denom
    lo = np.clip(centre - half, 0.0, 1.0)
    hi = np.clip(centre + half, 0.0, 1.0)
    # exact endpoints at the extremes (avoid round-off like 1e-17)
    lo = np.where(count == 0, 0.0, lo)
    hi = np.where(count == n, 1.0, hi)
    if lo.ndim == 0:
        return float(lo), float(hi)
    return lo, hi


def basins_fractions_table(
    labels, *, confidence: float = 0.95, exclude: Iterable[Hashable] = ()
) -> pd.DataFrame:
    """Tidy table of basin fractions with Wilson confidence intervals.

    Parameters
    ----------
    labels : array_like or pandas.Series
        Labels of any shape.
    confidence : float, optional
        Two-sided coverage of the intervals, default 0.95.
    exclude : iterable, optional
        Labels left out (see :func:`basins_fractions`).

    Returns
    -------
    pandas.DataFrame
        Columns ``label, count, fraction, ci_low, ci_high``, one row per label,
        sorted by label (ints first, then text).
    """
    keys, counts = _label_counts(labels, exclude)
    n = int(counts.sum())
    if n == 0:
        return pd.DataFrame(
            {"label": pd.Series([], dtype=object), "count": pd.Series([], dtype=np.int64),
             "fraction": [], "ci_low": [], "ci_high": []}
        )
    lo, hi = wilson_interval(counts, np.full(len(counts), n), confidence=confidence)
    all_int = all(isinstance(k, (int, np.integer)) for k in keys)
    return pd.DataFrame(
        {
            "label": pd.Series(keys, dtype=np.int64 if all_int else object),
            "count": counts,
            "fraction": counts / n,
            "ci_low": np.atleast_1d(lo),
            "ci_high": np.atleast_1d(hi),
        }
    )
