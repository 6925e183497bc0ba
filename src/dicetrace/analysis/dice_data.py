"""Measured face probabilities of real non-cubic dice, transcribed with their sources.

Only numbers read in the cited text are here; what could not be read is
listed in :data:`NOT_TRANSCRIBED` instead of being guessed.

**Square cuboids, steel, thrown by hand** (:data:`GAZETTE_97_16`).  *The
Mathematical Gazette* 97 (March 2013), note 97.16, "Probability analysis for
rolls of a square cuboidal die", Table 1 (read in the copies at
studylib.net/doc/11118377 and apps.dtic.mil/sti/citations/AD1016860, the
latter a U.S. Naval Academy record).  Each die has two opposite y×y square
faces and four x×y faces; ``p`` is the share of the ``N`` throws that ended
with a square face uppermost.  The note takes the data from an older article
(its reference [1], "over 30 years ago") whose author cut the 15 dice from a
steel bar and had his students roll each one N times; the surface they were
rolled on is not stated in the part of the note that could be read.  Every
``p`` of the table is, to its three printed decimals, the ratio of exactly one
integer count to ``N`` (:attr:`MeasuredCuboids.count`), so the counts are
recovered without loss.

Face convention: a square face "uppermost" and "lowermost" are the same
event (the two square faces are opposite), so ``p`` is also the share of
throws that came to rest on a square face.
"""

from __future__ import annotations

import dataclasses

import numpy as np

__all__ = ["GAZETTE_97_16", "MeasuredCuboids", "NOT_TRANSCRIBED", "SOURCES"]


@dataclasses.dataclass(frozen=True)
class MeasuredCuboids:
    """Measured probabilities of a family of square cuboidal dice (two y×y faces, four x×y faces).

    Attributes
    ----------
    aspect : numpy.ndarray
        x/y of each die (x the length of the four long edges, y the side of
        the two square faces).
    p : numpy.ndarray
        Share of throws ending with a square face up, as printed.
    n : numpy.ndarray
        Throws of each die.
    source : str
        Citation, with the table the numbers come from.
    """

    aspect: np.ndarray
    p: np.ndarray
    n: np.ndarray
    source: str

    def __post_init__(self) -> None:
        for name in ("aspect", "p", "n"):
            arr = np.asarray(getattr(self, name), dtype=np.int64 if name == "n" else float)
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)
        if not (self.aspect.shape == self.p.shape == self.n.shape):
            raise ValueError("aspect, p and n must have the same length")

    def __len__(self) -> int:
        return len(self.aspect)

    @property
    def count(self) -> np.ndarray:
        """Throws that ended with a square face up: the integer nearest ``p·n``.

        The only integer whose ratio to ``n`` rounds to the printed ``p``, for
        every die of :data:`GAZETTE_97_16` (checked in the tests).
        """
        return np.rint(self.p * self.n).astype(np.int64)

    def as_frame(self):
        """The table as a pandas DataFrame: ``aspect, p, n, count``."""
        import pandas as pd

        return pd.DataFrame({"aspect": self.aspect, "p": self.p, "n": self.n, "count": self.count})


#: The Mathematical Gazette 97 (2013), note 97.16, Table 1: 15 steel square cuboids thrown by hand.
GAZETTE_97_16 = MeasuredCuboids(
    aspect=[0.47, 0.63, 0.75, 0.81, 0.93, 0.97, 1.16, 1.23, 1.44, 1.55, 1.60, 1.71, 1.87, 2.12, 2.65],
    p=[0.916, 0.738, 0.548, 0.496, 0.399, 0.385, 0.148, 0.154, 0.052, 0.040, 0.017, 0.031, 0.009, 0.007, 0.006],
    n=[332, 840, 799, 740, 516, 530, 1011, 532, 654, 606, 702, 609, 680, 275, 503],
    source=(
        'The Mathematical Gazette 97 (March 2013), note 97.16, "Probability analysis for rolls of a square '
        "cuboidal die\", Table 1 (data of its reference [1]: 15 dice cut from a steel bar, each rolled N times "
        "by students)"
    ),
)

#: The papers behind the data and the baseline models (:mod:`dicetrace.analysis.fairness`).
SOURCES = {
    "gazette": GAZETTE_97_16.source,
    "riemer_stoyan_obreschkow": (
        'W. Riemer, D. Stoyan, D. Obreschkow, "Cuboidal dice and Gibbs distributions", Metrika (published '
        "online 2013; 77(2):247-256, 2014), doi:10.1007/s00184-013-0435-y, arXiv:1302.3925"
    ),
    "pender_uhrin": (
        'G. A. T. Pender, M. Uhrin, "Predicting non-square 2D dice probabilities", arXiv:1407.6307 (2014), '
        "University College London"
    ),
}

#: What this module does not hold, and why: the text could not be read beyond what is cited above.
NOT_TRANSCRIBED = {
    "riemer_stoyan_obreschkow": (
        "Their own control experiment with a single cuboid (their Section 3), the literature data they "
        "collect and their fitted Gibbs parameters: only the abstract and introduction of arXiv:1302.3925 "
        "could be read (it says the experiments show the surface the dice fall on changes the "
        "probabilities); no number of theirs is transcribed here."
    ),
    "pender_uhrin": (
        "Their rolls of long bars of several side ratios: only the abstract and the start of the introduction of "
        "arXiv:1407.6307 could be read (the formula implemented in dicetrace.analysis.fairness.pender_uhrin_ratio; "
        "their measured ratios somewhat closer to 1 than the formula), and UCL's news item on the paper (23 June "
        "2014: planks of several side ratios, rolled until \"the ten thousandth test roll\"); neither gives a measured "
        "number, so none is transcribed (dicetrace.studies.study_bars compares the formula alone)."
    ),
    "gazette_surface": (
        "The surface the Gazette note's dice were rolled on and how they were thrown: not in the part of the "
        "note that could be read (the introduction and Table 1)."
    ),
}
