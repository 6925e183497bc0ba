"""Transient chaos and convergence of outcome maps, measured with the simulator: neighbouring throws, FTLE maps, certificates.

* :func:`throw_divergence` / :func:`throw_lyapunov`: how fast a throw and its
  neighbour part (the finite-time Lyapunov exponent of one throw);
* :func:`ftle_on_slice`: that exponent over a 2-D window (the FTLE field);
* :func:`certify_map`: whether an outcome map is converged, from its agreement
  with a tighter integration against the chaos floor at the grid's spacing.

The pure measures these build on are :mod:`dicetrace.analysis.lyapunov` and
:mod:`dicetrace.analysis.agreement`; the slices, windows and batches are
those of :mod:`dicetrace.analysis.simulator`.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import replace

import numpy as np

from dicetrace.integrators import INTEGRATORS
from dicetrace.params import Config
from dicetrace.simulate import Record, simulate
from dicetrace.status import Status

from .agreement import agreement
from .grouping import UNSETTLED_LABEL
from .lyapunov import finite_time_lyapunov
from .simulator import BATCH_POINTS, _resolve_config, _run, resolve_slice, resolve_window, window_points

__all__ = ["DIVERGENCE_TIME_SCALE_S", "throw_divergence", "throw_lyapunov", "FTLEMap", "ftle_on_slice",
           "MapCertificate", "certify_map", "converged_verdict"]

#: Time scale (s) that turns velocities into lengths in the state distance of :func:`throw_divergence`.
DIVERGENCE_TIME_SCALE_S = 0.01


def throw_divergence(
    ic,
    *,
    delta: float = 1e-9,
    direction=None,
    config: Config | None = None,
    preset: str = "seed",
    time_scale_s: float = DIVERGENCE_TIME_SCALE_S,
    rng: np.random.Generator | int | None = 0,
    **overrides,
) -> tuple[np.ndarray, np.ndarray]:
    """Distance in state space between a throw and its neighbour, step by step.

    The neighbour starts at ``ic + delta * |ic| * u`` (``u`` a unit 6-vector:
    ``direction`` normalised, or random from ``rng``).  The distance of two
    states is that of the vectors (the eight node positions, cm; ``tau`` times
    the centre-of-mass velocity and ``tau`` times ``half_side · ω``, cm), with
    ``tau = time_scale_s``: positions and velocities weighed at the time scale
    of a bounce.  Both throws run with the same configuration (per-step
    states recorded) until the shorter one ends.

    Returns
    -------
    t_s, d : numpy.ndarray
        Times (s) and distances (cm), from t = 0.
    t_contact_s : float
        When the first throw first touches the ground (its bouncing phase
        starts); ``nan`` if it never does.
    """
    cfg = _resolve_config(config, preset, overrides)
    ic = np.asarray(ic, dtype=float)
    if direction is None:
        u = np.random.default_rng(rng).standard_normal(6)
    else:
        u = np.asarray(direction, dtype=float)
    if u.shape != (6,) or not np.linalg.norm(u) > 0:
        raise ValueError(f"direction must be a non-zero 6-vector, got {direction!r}")
    if not (delta > 0 and math.isfinite(delta)):
        raise ValueError(f"delta must be a finite number > 0, got {delta!r}")
    scale = float(np.linalg.norm(ic)) or 1.0
    ic2 = ic + delta * scale * u / np.linalg.norm(u)
    rec = Record(states=True, energy=False)
    a, b = simulate(ic, config=cfg, record=rec), simulate(ic2, config=cfg, record=rec)
    n = min(len(a.trace.t_s), len(b.trace.t_s))
    half, inertia = cfg.preset.half_side_cm, cfg.preset.inertia

    def state(tr):
        return np.concatenate(
            [tr.node_pos[:n].reshape(n, 24), time_scale_s * tr.cm_vel[:n], time_scale_s * half * tr.L[:n] / inertia],
            axis=1,
        )

    d = np.linalg.norm(state(a.trace) - state(b.trace), axis=1)
    t_contact = a.contact_steps[1] * a.dt_s if len(a.contact_steps) > 1 else math.nan
    return a.trace.t_s[:n].copy(), d, float(t_contact)


def throw_lyapunov(ic, *, delta: float = 1e-9, saturation: float | None = 1e-2, phase: str = "bouncing",
                   **options):
    """Finite-time Lyapunov exponent of a throw (1/s) from :func:`throw_divergence`.

    The exponent is the slope of ``ln d`` against ``t`` until the distance
    reaches ``saturation`` cm (default 0.01 cm, a hundredth of the die's half
    side: the pair still diverges linearly), from the first ground contact
    (``phase="bouncing"``, default: free flight only shears the pair apart
    linearly in time) or from the first step (``phase="whole"``); see
    :func:`dicetrace.analysis.lyapunov.finite_time_lyapunov`.  ``options`` go
    to :func:`throw_divergence`.
    """
    if phase not in ("bouncing", "whole"):
        raise ValueError(f"phase must be 'bouncing' or 'whole', not {phase!r}")
    t, d, t_contact = throw_divergence(ic, delta=delta, **options)
    if phase == "bouncing" and not math.isfinite(t_contact):
        raise ValueError("the throw never touches the ground: it has no bouncing phase")
    return finite_time_lyapunov(t, d, saturation=saturation, t_min=t_contact if phase == "bouncing" else None)


@dataclasses.dataclass(frozen=True)
class FTLEMap:
    """A finite-time Lyapunov exponent field over a window of a slice.

    ``ftle`` (1/s) and ``outcome`` are indexed ``[i, j]`` like the axes
    ``x``, ``y``; ``ftle`` is ``nan`` where the fit failed (a throw that
    never touches the ground, or too short a linear range).
    """

    x: np.ndarray
    y: np.ndarray
    ftle: np.ndarray
    stderr: np.ndarray
    outcome: np.ndarray


def ftle_on_slice(
    window,
    res,
    slice_spec="seed",
    *,
    config: Config | None = None,
    preset: str = "seed",
    delta: float = 1e-9,
    phase: str = "bouncing",
    rng: int = 0,
    **overrides,
) -> FTLEMap:
    """The FTLE field of a 2-D window: :func:`throw_lyapunov` at every grid node.

    Every node's neighbour is displaced in the same random direction of IC
    space (``rng``), so the field compares like with like; its ridges are
    expected along the cell borders, where neighbouring throws part.
    Serial (two traced throws per node): keep ``res`` modest (32² ≈ 10 s).
    """
    sl = resolve_slice(slice_spec)
    cfg = _resolve_config(config, preset, overrides)
    pts, shape, axes = window_points(resolve_window(window, 2), res)
    if len(shape) != 2:
        raise ValueError(f"ftle_on_slice needs a 2-D window, got shape {shape}")
    conv = cfg.preset.l_convention if sl.l_convention == "preset" else sl.l_convention
    ics = cfg.to_preset_convention(sl.to_ics(pts), conv)
    u = np.random.default_rng(rng).standard_normal(6)
    lam = np.full(len(pts), np.nan)
    err = np.full(len(pts), np.nan)
    out = np.empty(len(pts), dtype=np.int64)
    for i, ic in enumerate(ics):
        roll = simulate(ic, config=cfg)
        out[i] = roll.outcome if roll.status == Status.SETTLED else UNSETTLED_LABEL
        try:
            fit = throw_lyapunov(ic, delta=delta, direction=u, config=cfg, phase=phase)
        except ValueError:
            continue
        lam[i], err[i] = fit.exponent, fit.stderr
    return FTLEMap(axes[0], axes[1], lam.reshape(shape), err.reshape(shape), out.reshape(shape))


@dataclasses.dataclass(frozen=True)
class MapCertificate:
    """Whether an outcome map is converged: its agreement under a tighter integration and under a tiny IC change.

    ``tightened``: the map against itself computed with the tolerance (an
    adaptive integrator) or the step (a fixed one) 10× smaller.
    ``floor``: the map against itself at ICs moved by a tenth of the grid
    spacing (a random direction per point): the chaos floor at the grid's
    resolution, the best agreement any numerics can show there.  The map is
    ``converged`` when ``tightened`` is not below ``floor`` (their Wilson
    intervals overlap or ``tightened`` is higher).
    """

    tightened: object  # analysis.agreement.Agreement
    floor: object
    converged: bool
    labels: np.ndarray
    tight_config: Config


def _tightened(cfg: Config, factor: float) -> Config:
    num = cfg.numerics
    if INTEGRATORS[num.integrator].adaptive:
        # uniform: a tolerance that loosens over the throw (tol_growth) is never tighter than its start,
        # while both would reach the same loosest tolerance late in a throw
        return replace(cfg, numerics=replace(num, tol=num.tol / factor, tol_growth=0.0))
    return replace(cfg, numerics=replace(num, dt_s=num.dt_s / factor))


def certify_map(window, res, slice_spec="seed", *, config: Config | None = None, preset: str = "seed",
                factor: float = 10.0, rng: int = 0, base=None, **overrides) -> MapCertificate:
    """The convergence certificate of the outcome map of a 2-D window (see :class:`MapCertificate`).

    ``base``: the map's outcomes at ``config`` if already simulated (any
    shape holding the grid's points in :func:`window_points` order), so that
    only the tightened and the moved maps are run.
    """
    sl = resolve_slice(slice_spec)
    cfg = _resolve_config(config, preset, overrides)
    pts, shape, axes = window_points(resolve_window(window, 2), res)
    tight = _tightened(cfg, float(factor))
    if base is None:
        base = _run(sl, cfg, pts, False, BATCH_POINTS).outcome
    else:
        base = np.asarray(base).ravel()
        if base.size != len(pts):
            raise ValueError(f"base has {base.size} outcomes for a grid of {len(pts)} points")
    fine = _run(sl, tight, pts, False, BATCH_POINTS).outcome
    spacing = np.array([a[1] - a[0] if len(a) > 1 else 0.0 for a in axes])
    angle = np.random.default_rng(rng).uniform(0, 2 * np.pi, len(pts))
    moved = pts + 0.1 * spacing * np.stack([np.cos(angle), np.sin(angle)], axis=1)
    near = _run(sl, cfg, moved, False, BATCH_POINTS).outcome
    a_tight, a_floor = agreement(base, fine), agreement(base, near)
    converged = a_tight.ci[1] >= a_floor.ci[0]
    return MapCertificate(a_tight, a_floor, bool(converged), base.reshape(shape), tight)


def converged_verdict(cert) -> bool:
    """Converged: the certificate is not below the chaos floor (:func:`certify_map`'s rule) and its agreement
    beats chance (Cohen's κ more than 3 standard errors above 0; where the floor itself is at chance, a map at
    chance would otherwise pass)."""
    t = cert.tightened
    return bool(cert.converged and t.kappa - 3 * t.kappa_stderr > 0)
