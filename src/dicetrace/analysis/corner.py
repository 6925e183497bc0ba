"""The corner balance of the simulated die: its two unstable rates, and which face comes up around it.

A die balanced on one corner (its centre of mass straight above one node)
is an equilibrium with **two** unstable directions: it can fall toward any
horizontal direction.  Linearised about the balance (docs/model.md: 8 node
masses, the model's isotropic inertia ``I``, one node on the penalty
ground), the motion in any vertical plane through the pivot is

* **rigid pivot** (the pivot node neither slips nor sinks):
  ``(I + m d²) θ'' = m g d θ`` with ``d = √3·half`` (the half body diagonal),
  so ``λ₀ = √(m g d / I_pivot)``, ``I_pivot = I + m d²``; the same in every
  vertical plane because ``I`` is isotropic: a double eigenvalue ``+λ₀``
  (two unstable directions), a double ``−λ₀``, and a neutral spin about the
  vertical.  For the model's ``I = (16/3)·half²`` and ``g = 980`` cm/s²:
  ``λ₀ = 21.516`` /s (the edge saddle's is 22.80 /s: ``d = √2``).
* **the ground spring** does not enter at first order: tilting by ``θ``
  moves the centre of mass down by ``d θ²/2`` and the pivot's normal force
  acts along the vertical, so the vertical mode (``8 Z'' = −k Z − m g γ Z'``,
  a damped oscillation at √(k/8) ≈ 250 rad/s) decouples from the tilt.
* **friction** holds the pivot horizontally.  The ``seed`` preset's law
  ``μ P u/σ`` is of degree 0 in the velocities: an exponentially growing
  tilt needs a friction force that grows with it, which that law gives only
  for a slip velocity of second order: the linear rate is the rigid one.
  The ``physical`` preset's law is linear for slips well below ``v_reg``:
  ``F = −c u`` with ``c = μ m g / v_reg`` (940.8 for ``v_reg = 10`` cm/s),
  and the pivot slips.  With the centre's horizontal position ``X``:
  ``m X'' = −c (X' − d θ')`` and ``I θ'' = m g d θ − d F``, whose
  characteristic polynomial is
  ``I m s³ + (I + m d²) c s² − m² g d s − m g d c = 0`` (it tends to the rigid
  pivot as ``c → ∞``): its positive root is the unstable rate (23.127 /s,
  7.5 % above the rigid one), the others a stable rate and the fast decay
  of the slip.

:func:`corner_balance` gives these numbers for a configuration;
:func:`corner_release` releases the die at rest (or with a small angular
velocity) tilted by ``tilt`` toward the horizontal direction ``phi`` from
the balance; :func:`corner_release_rate` fits the growth of the tilt over
the linear range; :func:`release_outcome` and :func:`sector_boundaries` map
which face comes up around the balance, with the sectors' borders bisected.

Directions: the pivot is node 1 (body (−, −, −)), the body diagonal through
it vertical, and the horizontal projection of its edge to node 5 (body +x)
at azimuth 0; its edges to nodes 3 (+y) and 2 (+z) then lie at azimuths
120° and 240°, the three faces at the pivot (1, 2, 3) in between (azimuths
60° for face 2, 180° for face 1, 300° for face 3) and the faces that can
come up on top are 4, 5, 6.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import replace

import numpy as np

from dicetrace.params import Config
from dicetrace.simulate import Record, simulate

from .release import Release, fit_release, never_reached
from .simulator import _resolve_config

__all__ = ["CornerBalance", "corner_balance", "corner_orientation", "corner_release", "corner_tilt",
           "CornerRelease", "corner_release_rate", "release_outcome", "face_map", "sector_boundaries",
           "EDGE_AZIMUTHS", "FACE_AZIMUTHS", "PIVOT_NODE"]

#: The pivot node (index 0: node 1) and the azimuths (rad) of its three edges and three faces.
PIVOT_NODE = 0
EDGE_AZIMUTHS = (0.0, 2 * math.pi / 3, 4 * math.pi / 3)
#: Face (at the pivot) -> azimuth of its centre's horizontal projection.
FACE_AZIMUTHS = {2: math.pi / 3, 1: math.pi, 3: 5 * math.pi / 3}
_M = 8.0  # the die's mass in node masses


@dataclasses.dataclass(frozen=True)
class CornerBalance:
    """The corner balance of one configuration and its linearisation (units: cm, s, node masses).

    ``rate``: the preset's unstable rate (1/s, twice: two unstable directions);
    ``rate_rigid``: the rigid pivot's; ``rate_change``: ``rate / rate_rigid − 1``;
    ``slip_c``: the linear friction coefficient of the pivot (inf: no slip at
    first order); ``roots``: every root of the planar characteristic
    polynomial; ``vertical``: the two eigenvalues of the vertical mode.
    """

    preset: str
    friction: str
    d: float
    inertia: float
    inertia_pivot: float
    depth_eq: float
    z_cm: float
    rate_rigid: float
    rate: float
    rate_change: float
    slip_c: float
    roots: tuple[float, ...]
    vertical: tuple[complex, complex]

    def as_dict(self) -> dict:
        out = dataclasses.asdict(self)
        out["vertical"] = [[v.real, v.imag] for v in self.vertical]
        return out


def corner_balance(*, config: Config | None = None, preset: str = "seed", **overrides) -> CornerBalance:
    """The corner balance of a configuration: geometry, compression, and the rates of its linearisation."""
    cfg = _resolve_config(config, preset, overrides)
    p = cfg.preset
    g, half, inertia = abs(float(p.g)), float(p.half_side_cm), float(p.inertia)
    d = math.sqrt(3.0) * half
    ip = inertia + _M * d * d
    depth = _M * g / float(p.k)  # one node carries the weight: k·depth = m g
    rigid = math.sqrt(_M * g * d / ip)
    if p.friction == "spectral":  # degree 0 in the velocities: no slip at first order (module docstring)
        c = math.inf
        roots = (rigid, -rigid)
        rate = rigid
    else:
        c = float(p.mu) * _M * g / float(p.v_reg_cm_s)
        r = np.roots([inertia * _M, ip * c, -_M * _M * g * d, -_M * g * d * c])
        roots = tuple(sorted(float(v.real) for v in r))
        rate = max(roots)
    damp = _M * g * float(p.gamma)  # k·depth·γ: the normal force's damping at the balance
    vert = np.roots([_M, damp, float(p.k)])
    return CornerBalance(str(p.name), str(p.friction), d, inertia, ip, depth,
                         d - depth, rigid, rate, rate / rigid - 1.0, c, roots,
                         (complex(vert[0]), complex(vert[1])))


def _axis_angle(axis, angle: float) -> np.ndarray:
    a = np.asarray(axis, dtype=float)
    a = a / np.linalg.norm(a)
    k = np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])
    return np.eye(3) + math.sin(angle) * k + (1.0 - math.cos(angle)) * (k @ k)


def _balance_rotation() -> np.ndarray:
    """World-from-body rotation putting node 1's body diagonal straight down, its edge to node 5 at azimuth 0."""
    b = -np.ones(3) / math.sqrt(3.0)  # node 1's direction from the centre
    down = np.array([0.0, 0.0, -1.0])
    v = np.cross(b, down)
    s, c = float(np.linalg.norm(v)), float(b @ down)
    r1 = _axis_angle(v, math.atan2(s, c))
    ex = r1 @ np.array([1.0, 0.0, 0.0])
    return _axis_angle([0.0, 0.0, 1.0], -math.atan2(ex[1], ex[0])) @ r1


_R0 = _balance_rotation()


def corner_orientation(tilt: float = 0.0, phi: float = 0.0) -> np.ndarray:
    """The die on node 1, tilted by ``tilt`` (rad), its centre moved toward azimuth ``phi``: a rotation matrix."""
    return _axis_angle([-math.sin(phi), math.cos(phi), 0.0], float(tilt)) @ _R0


def _release_config(cfg: Config, tilt: float, t_max_s: float | None) -> Config:
    p = cfg.preset
    d = math.sqrt(3.0) * p.half_side_cm
    z0 = d * math.cos(tilt) - _M * abs(p.g) / p.k  # the pivot at the depth that carries the weight
    num = cfg.numerics if t_max_s is None else replace(cfg.numerics, t_max_s=float(t_max_s))
    return replace(cfg, preset=replace(p, z0_cm=z0), numerics=num)


def corner_release(cfg: Config, tilt: float, phi: float, *, spin: float = 0.0, t_max_s: float | None = None,
                   record=None):
    """The die released from its corner balance tilted by ``tilt`` toward ``phi``, at rest or turning.

    ``spin`` (rad/s): an angular velocity about the pivot that tilts the die
    toward ``phi + π/2`` (the centre of mass moves with the rigid rotation
    about the resting pivot).  Returns the :class:`~dicetrace.simulate.Roll`.
    """
    c = _release_config(cfg, tilt, t_max_s)
    ic = np.zeros(6)
    if spin:
        p = c.preset
        d = math.sqrt(3.0) * p.half_side_cm
        psi = phi + math.pi / 2
        omega = float(spin) * np.array([-math.sin(psi), math.cos(psi), 0.0])
        ic[:3] = np.cross(omega, [0.0, 0.0, d])  # the centre turns about the pivot below it
        sign = 1.0 if p.l_convention == "physical" else -1.0  # the program's L is the negative of the physical one
        ic[3:] = sign * p.inertia * omega
    return simulate(ic, config=c, orientation=corner_orientation(tilt, phi), record=record)


def corner_tilt(node_offsets: np.ndarray, node: int = PIVOT_NODE) -> tuple[np.ndarray, np.ndarray]:
    """Tilt (rad) of the centre of mass from straight above ``node``, and its azimuth (rad), per trace row."""
    up = -np.asarray(node_offsets)[:, node, :]
    return np.arctan2(np.hypot(up[:, 0], up[:, 1]), up[:, 2]), np.arctan2(up[:, 1], up[:, 0])


@dataclasses.dataclass(frozen=True)
class CornerRelease(Release):
    """The die released from its corner (:class:`~dicetrace.analysis.release.Release`), and the azimuth drift (rad)
    over the fit."""

    drift: float


def corner_release_rate(*, config: Config | None = None, preset: str = "physical", tilt0: float = 1e-7,
                        phi: float = 0.3, start: float = 100.0, saturation: float = 1e-3, t_max_s: float = 1.5,
                        spin_ratio: float = 0.0, **overrides) -> CornerRelease:
    """The unstable rate of the corner balance from the die released at rest at tilt ``tilt0`` toward ``phi``.

    The tilt's logarithm is fitted from ``start·tilt0`` (the stable
    directions have decayed) to ``saturation`` rad (``sin θ = θ`` to
    ``saturation²/6``).  ``drift``: how far the direction of the tilt turned
    from ``phi`` by the end of the fit (0 for a double eigenvalue).
    ``spin_ratio``: released turning at ``spin_ratio·λ₀·tilt0`` toward
    ``phi + π/2`` instead (:func:`corner_release`); the linear motion then
    leaves along ``phi + atan(spin_ratio)`` for a rigid pivot.
    ValueError when the tilt never reaches ``saturation``.
    """
    cfg = _resolve_config(config, preset, overrides)
    spin = float(spin_ratio) * corner_balance(config=cfg).rate_rigid * float(tilt0)
    roll = corner_release(cfg, float(tilt0), float(phi), spin=spin, t_max_s=t_max_s, record=Record(states=True))
    tr = roll.trace
    ok = tr.written
    t, (tilt, az) = tr.t_s[ok], corner_tilt(tr.node_offsets[ok])
    if not (tilt > start * tilt0).any():  # the fit must start inside the run, too
        raise never_reached(roll, tilt0, saturation)
    fit = fit_release(roll, t, tilt, tilt0=tilt0, start=start, saturation=saturation)
    end = int(np.argmax(tilt > saturation))
    drift = abs(math.remainder(float(az[end]) - float(phi), 2 * math.pi))
    return CornerRelease(fit.exponent, fit.stderr, fit.fit_range, roll.status.label, drift=drift)


def release_outcome(cfg: Config, tilt: float, phi: float, spin: float = 0.0) -> int:
    """The face that comes up after the release (:func:`corner_release`); −1 when the run did not settle."""
    roll = corner_release(cfg, tilt, phi, spin=spin)
    return int(roll.outcome) if roll.status.label == "settled" else -1


def face_map(cfg: Config, tilts, phis, spin_ratio: float = 0.0) -> np.ndarray:
    """Outcomes (len(tilts), len(phis)) of releases at each tilt and azimuth; ``spin_ratio``: spin = ratio·λ·tilt."""
    lam = corner_balance(config=cfg).rate
    return np.array([[release_outcome(cfg, float(a), float(f), spin_ratio * lam * float(a)) for f in phis]
                     for a in tilts], dtype=np.int64)


def _bisect(label_at, a: float, b: float, la, lb, tol: float) -> tuple[float, float, object, object, int]:
    """Bisect the parameter interval [a, b] whose ends carry labels la ≠ lb down to ``tol``; returns the bracket,
    the labels at its ends and the number of evaluations.  A third label met on the way is kept on the side
    where it changes (the bracket then ends on it)."""
    n = 0
    while b - a > tol:
        m = 0.5 * (a + b)
        lm = label_at(m)
        n += 1
        if lm == la:
            a = m
        else:
            b, lb = m, lm
    return a, b, la, lb, n


def sector_boundaries(cfg: Config, tilt: float, *, n_phi: int = 72, tol: float = 1e-9, spin_ratio: float = 0.0,
                      phis=None, labels=None) -> list[dict]:
    """The borders between outcome sectors on the circle of releases at ``tilt``, bisected in azimuth to ``tol``.

    ``phis``/``labels``: a coarse ring already computed (``n_phi`` equally
    spaced azimuths otherwise).  One row per change of label between
    neighbouring azimuths: ``phi`` (the bracket's middle, rad), ``error``
    (half the bracket), ``from``/``to`` (the labels either side), ``evals``.
    """
    lam = corner_balance(config=cfg).rate
    spin = spin_ratio * lam * float(tilt)
    if phis is None:
        phis = np.linspace(0.0, 2 * math.pi, int(n_phi), endpoint=False)
        labels = [release_outcome(cfg, tilt, float(f), spin) for f in phis]
    phis, labels = np.asarray(phis, dtype=float), list(labels)
    rows = []
    for i in range(len(phis)):
        j = (i + 1) % len(phis)
        if labels[i] == labels[j]:
            continue
        a, b = float(phis[i]), float(phis[j]) + (2 * math.pi if j == 0 else 0.0)
        a, b, la, lb, n = _bisect(lambda f: release_outcome(cfg, tilt, f, spin), a, b, labels[i], labels[j], tol)
        rows.append({"phi": math.fmod(0.5 * (a + b), 2 * math.pi), "error": 0.5 * (b - a), "from": la, "to": lb,
                     "evals": n})
    return rows
