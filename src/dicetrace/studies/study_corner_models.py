"""Study m (corner), its models: the ``make_config`` options of each part and :func:`config` (shared by
:mod:`dicetrace.studies.study_corner` and :mod:`dicetrace.studies.study_corner_render`)."""

from __future__ import annotations

from dicetrace.params import make_config

#: The model of each part: make_config options.
PHYSICAL = {"preset": "physical", "integrator": "contact-tsit5", "tol": 1e-10, "tol_growth": 0.0}
SEED_CONVERGED = {"preset": "seed", "integrator": "contact-adaptive", "tol": 1e-9}
SEED_DISCRETE = {"preset": "seed"}
#: The model of the converged maps and of every refinement and bisection on them: one uniform tight tolerance.
MAP_MODEL = HUNT_MODEL = SEED_CONVERGED
#: The converged model of studies j-l (its die released at rest, to show where its integrator stops).
STUDY_CONVERGED = {"preset": "seed", "integrator": "contact-adaptive", "tol": 1e-7}
#: The model of each face map.
MODEL_OPTS = {"physical": PHYSICAL, "seed-converged": SEED_CONVERGED, "seed-discrete": SEED_DISCRETE}


def config(opts: dict):
    """The configuration of one model's options."""
    kw = dict(opts)
    return make_config(kw.pop("preset"), **kw)
