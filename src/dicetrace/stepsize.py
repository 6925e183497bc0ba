"""The automatic time step (``dt = "auto"``): impact speeds, stiff rates and the step they allow.

Below the configuration layer: it reads only the integrator table and the
fields of a :class:`~dicetrace.params.Preset` it is given.
"""

from __future__ import annotations

import math

import numpy as np

from dicetrace.integrators import get_integrator


#: ``dt = "auto"`` keeps the stiffest rate times dt below this fraction of the bound.
AUTO_DT_SAFETY = 0.5
#: Forward Euler: energy gain allowed per contact (a contact lasts π/ω, gain ≈ e^{π·ω·dt/2} − 1).
AUTO_DT_FE_GAIN = 0.01
#: ``dt = "auto"`` never picks a step above this (the program's dt), s.
AUTO_DT_MAX_S = 1e-3
#: ``dt = "auto"`` refuses when the time cap would take more steps than this.
AUTO_DT_MAX_STEPS = 20_000_000
#: Inverse effective mass of a corner along the ground, at most 1/8 + 3·3/16 per node mass.
_INV_MASS_NODE = 11.0 / 16.0
#: Speed added to the drop speed when ``dt = "auto"`` is not told the ICs, cm/s.
AUTO_DT_DEFAULT_THROW_CM_S = 300.0


def impact_speed_cm_s(ics, preset) -> float:
    """Bound on any node's speed at the first impact over ICs (m, 6) or one IC, cm/s.

    Free flight conserves energy: a node moves at most at |U| + |ω|·r (r the reach, the cube's √3·half),
    and the fall to the ground adds √(2·|g|·(z0 − half))·... (bounded by
    adding the drop speed).  |ω| ≤ |L| / I, I the smallest principal moment (either sign convention).
    """
    a = np.atleast_2d(np.asarray(ics, dtype=float))
    u = np.linalg.norm(a[:, :3], axis=1)
    w = np.linalg.norm(a[:, 3:6], axis=1) / preset.inertia
    drop = math.sqrt(max(0.0, 2.0 * abs(preset.g) * max(preset.z0_cm - preset.half_side_cm, 0.0)))
    return float(np.max(u + w * _reach_cm(preset))) + drop


def _reach_cm(preset) -> float:
    """The nodes' largest distance from the centre of mass: the cube's √3·half side, a box's or loaded die's
    ``body.reach_cm``."""
    if getattr(preset, "is_cube", True):
        return math.sqrt(3.0) * preset.half_side_cm
    return preset.body.reach_cm


def _inv_mass_node(preset) -> float:
    """A node's largest inverse effective mass along the ground (the cube's 11/16, ``body.Body.inv_mass_node``)."""
    return _INV_MASS_NODE if getattr(preset, "is_cube", True) else preset.body.inv_mass_node


def stiff_rates(preset, v_impact_cm_s: float) -> tuple[float, float]:
    """(spring rate, friction rate), 1/s, for impacts at ``v_impact_cm_s``.

    Spring: √k·(1 + γ·v) (the damping P = k·d·(1 − γ·u_z) adds k·γ·d with
    d ≲ v/√k).  Friction (per-node law only): μ·P/(m_eff·v_reg) with the peak
    normal force P ≈ √k·v·(1 + γ·v): the rate of the regularised law where a
    corner sticks at the peak of an impact.
    """
    w = math.sqrt(preset.k)
    v = max(float(v_impact_cm_s), 0.0)
    spring = w * (1.0 + preset.gamma * v)
    fric = 0.0
    if preset.friction == "per-node":
        fric = preset.mu * _inv_mass_node(preset) * w * v * (1.0 + preset.gamma * v) / preset.v_reg_cm_s
    return spring, fric


def auto_dt(
    preset,
    integrator: str,
    *,
    v_impact_cm_s: float | None = None,
    t_max_s: float = 60.0,
    substeps: int = 8,
) -> float:
    """The time step ``dt = "auto"`` picks, s, or ValueError (one line) when none fits.

    dt keeps the spring's rate λ (with damping, :func:`stiff_rates`) at
    ``AUTO_DT_SAFETY`` of the integrator's bound (``IntegratorSpec.stability_bound``):
    dt = safety·bound/λ, per sub-step for ``contact-substep``.  The
    error-controlled schemes (``IntegratorSpec.adaptive``: contact-adaptive,
    contact-dop853, contact-tsit5) get ``AUTO_DT_MAX_S``:
    their dt is only the cadence of the stop test and the longest sub-step,
    and their error control, not dt, keeps the sub-steps stable (the stability
    map, ``dicetrace stability``, finds every one of them stable at every dt
    up to 16 ms for k up to 5·10⁷), so a dt from an explicit bound would only
    cut their sub-steps at more step ends.  The stick
    rate of the per-node friction law is left out: the friction force is
    bounded by μ·P, so an unresolved stick chatters by ~dt·μ·P/m but does not
    grow (the stability map in analysis/accuracy checks this), and
    ``contact-substep`` resolves it adaptively.  Forward Euler gets ω·dt = 2·gain/π
    (energy gain ``AUTO_DT_FE_GAIN`` per contact).  Never above
    ``AUTO_DT_MAX_S``.  Refuses when t_max_s/dt exceeds ``AUTO_DT_MAX_STEPS``.

    Parameters
    ----------
    v_impact_cm_s
        Largest node speed at impact, cm/s (see :func:`impact_speed_cm_s`);
        None: the drop speed from z0 plus ``AUTO_DT_DEFAULT_THROW_CM_S``.
    """
    spec = get_integrator(integrator)
    if v_impact_cm_s is None:
        drop = math.sqrt(max(0.0, 2.0 * abs(preset.g) * max(preset.z0_cm - preset.half_side_cm, 0.0)))
        v_impact_cm_s = drop + AUTO_DT_DEFAULT_THROW_CM_S
    spring, _ = stiff_rates(preset, v_impact_cm_s)
    if spec.adaptive:
        dt = AUTO_DT_MAX_S
    elif spec.stability_bound == 0.0:
        dt = 2.0 * AUTO_DT_FE_GAIN / math.pi / spring
    elif spec.substepped:
        dt = substeps * AUTO_DT_SAFETY * spec.stability_bound / spring
    else:
        dt = AUTO_DT_SAFETY * spec.stability_bound / spring
    dt = min(dt, AUTO_DT_MAX_S)
    steps = t_max_s / dt
    if steps > AUTO_DT_MAX_STEPS:
        raise ValueError(
            f"dt auto: {integrator} needs dt <= {dt:.3g} s at k = {preset.k:g} and impact speed "
            f"{v_impact_cm_s:.0f} cm/s, {steps:.3g} steps for a {t_max_s:g} s time cap "
            f"(budget {AUTO_DT_MAX_STEPS:.3g}): use contact-substep, a smaller k or a shorter time cap"
        )
    return dt
