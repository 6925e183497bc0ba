"""The triple-point law: what a corner balance predicts for the triple points of a 2-D outcome map, and its measures.

A triple point of a map of the seed slice is where the slice crosses the stable set of a corner balance
(:mod:`dicetrace.analysis.corner`, :mod:`dicetrace.analysis.corner_slice`).  Three predictions follow from the
balance and are measured here:

* **Opposite faces never close.**  A balance on one node can bring up only the three faces around the opposite
  node, which are mutually adjacent; faces ``i`` and ``7 − i`` are opposite and never both among them.  So a box of a
  map whose three faces hold an opposite pair cannot close on a point (:func:`has_opposite_pair`,
  :func:`closure_table`, with Clopper–Pearson limits: :func:`binomial_limits`).
* **Logarithmic spirals.**  Linearised about a corner balance spinning at Ω about the vertical (docs/model.md §12,
  :func:`spinning_corner`), with the pivot held: ``A u″ − i C Ω u′ − m g d u = 0`` for the complex tilt ``u`` (world
  frame), ``A = I + m d²``, ``C = I``.  Its roots are ``s = i ω_p ± √(λ₀² − ω_p²)`` with ``ω_p = C Ω / 2A``: the tilt
  grows at ``λ(Ω) = √(λ₀² − ω_p²)`` while its direction turns at ``ω_p`` in the world, i.e. at ``Ω − ω_p`` against
  the die, which itself turns at Ω.  Which face comes up is set by the fall's direction *on the die*, reached after
  ``ln(θ_s/a)/λ`` for an amplitude ``a ∝ r`` (the distance from the point), so the borders between the three faces
  turn by ``W = (Ω − ω_p)·ln 10/λ(Ω)`` per decade of ``r``.  :func:`fit_spiral` measures ``W`` from border angles on
  circles, with the slice's own linear distortion fitted beside it.
* **Closest approach against distance.**  ``D_min`` of the throws near a point against their distance ``r``
  (:func:`stretch_fit`: ``D_min = J r^β``), and the share of a window's throws with ``D_min < D``
  (:func:`share_curve`, :func:`loglog_slope`) against the share the located points predict,
  ``Σ_i (area where J_i r^β_i < D)`` (:func:`predicted_share`).  For ``β = 1`` (``D_min ≈ J r``) that share is
  ``Σ π (D/J_i)²``: a ``D²`` law.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

import numpy as np
from scipy import optimize, stats

__all__ = ["has_opposite_pair", "binomial_limits", "closure_table", "SpinningCorner", "spinning_roots", "pivot_friction", "spinning_corner",
           "spinning_release", "release_borders", "border_tracks", "SpiralFit", "fit_spiral", "spiral_angles", "stretch_fit", "share_curve", "loglog_slope",
           "predicted_share", "cluster_boxes"]

LN10 = math.log(10.0)
#: Bound of the spiral fit's log squeeze (|ln q| ≤ LQ_MAX).
LQ_MAX = math.log(1e6)


# --------------------------------------------------------------------------- 1. opposite faces


def has_opposite_pair(faces) -> bool:
    """Whether the faces (1 … 6) hold a pair of opposite faces, ``i`` and ``7 − i``."""
    f = {int(v) for v in faces}
    return any(7 - v in f for v in f)


def binomial_limits(k: int, n: int, cl: float = 0.95) -> tuple[float, float]:
    """Clopper–Pearson central interval of a fraction ``k/n`` at confidence ``cl``; where ``k`` is 0 (or ``n``), the
    one-sided bound at ``cl`` (0 closed out of 10: the upper bound 1 − 0.05^(1/10) = 0.259).  (nan, nan) for n = 0."""
    if n <= 0:
        return math.nan, math.nan
    if k == 0:
        return 0.0, float(1.0 - (1.0 - cl) ** (1.0 / n))
    if k == n:
        return float((1.0 - cl) ** (1.0 / n)), 1.0
    a = (1.0 - cl) / 2.0
    return float(stats.beta.ppf(a, k, n - k + 1)), float(stats.beta.ppf(1.0 - a, k + 1, n - k))


def closure_table(rows: Sequence[dict]) -> dict:
    """Counts of refined boxes by class (``"opposite"``: the three faces hold an opposite pair; ``"adjacent"``: the
    three are mutually adjacent) and outcome (``"closed"``: refined to a point, ``"split"``, ``"unresolved"``: any
    other status), with the closing fraction of the resolved boxes and its 95 % limits.  ``rows``: ``{"faces":
    [...], "status": ...}`` (status ``"vertex"`` is closed)."""
    out = {}
    for cls in ("opposite", "adjacent"):
        sel = [r for r in rows if has_opposite_pair(r["faces"]) == (cls == "opposite")]
        closed = sum(r["status"] == "vertex" for r in sel)
        split = sum(r["status"] == "split" for r in sel)
        n = closed + split
        lo, hi = binomial_limits(closed, n)
        out[cls] = {"n": len(sel), "closed": closed, "split": split, "unresolved": len(sel) - n,
                    "fraction": closed / n if n else math.nan, "lo95": lo, "hi95": hi}
    return out


def cluster_boxes(boxes: np.ndarray, faces: Sequence[tuple], *, reach: int = 1) -> list[list[int]]:
    """Clusters of candidate boxes (grid indices (n, 2)) that are one junction: boxes with the same three faces
    within ``reach`` grid intervals of each other in both axes (chained).  Returns lists of row indices, each sorted,
    in order of their first box."""
    b = np.asarray(boxes, dtype=np.int64).reshape(-1, 2)
    n = len(b)
    parent = list(range(n))

    def find(k):
        while parent[k] != k:
            parent[k] = parent[parent[k]]
            k = parent[k]
        return k

    for i in range(n):
        for j in range(i + 1, n):
            if tuple(faces[i]) == tuple(faces[j]) and np.all(np.abs(b[i] - b[j]) <= reach):
                ri, rj = find(i), find(j)
                if ri != rj:
                    parent[max(ri, rj)] = min(ri, rj)
    groups: dict[int, list[int]] = {}
    for i in range(n):
        groups.setdefault(find(i), []).append(i)
    return sorted(groups.values(), key=lambda g: g[0])


# --------------------------------------------------------------------------- 2. spirals


@dataclasses.dataclass(frozen=True)
class SpinningCorner:
    """The corner balance spinning at ``omega`` (rad/s) about the vertical (module docstring, docs/model.md §12).

    ``slip_c``: the pivot's linear friction coefficient (inf: held); ``root``: the unstable root of the tilt's
    characteristic polynomial, complex, in the world frame; ``lam``: its real part, ``omega_p``: its imaginary part
    (the direction's turn in the world); ``body_rate``: ``omega − omega_p``, the direction's turn against the die;
    ``winding``: the borders' turn per decade of distance, ``body_rate·ln 10/lam`` (rad).  Beside it, the other
    readings of the law: ``winding_issue`` (``omega·ln 10/lam``), ``winding_world`` (``omega_p·ln 10/lam``) and
    ``winding_held`` (the held pivot's ``body_rate·ln 10/lam``, which `seed`'s friction does not give a spinning
    die)."""

    omega: float
    slip_c: float
    lam0: float
    lam: float
    omega_p: float
    body_rate: float
    winding: float
    winding_issue: float
    winding_world: float
    winding_held: float
    lam_held: float
    omega_p_held: float

    def as_dict(self) -> dict:
        return {k: (v if math.isfinite(v) else None) for k, v in dataclasses.asdict(self).items()}


def spinning_roots(omega: float, *, inertia: float, d: float, slip_c: float, g: float = 980.0,
                   mass: float = 8.0) -> np.ndarray:
    """The roots (complex, world frame) of the tilt ``u = u_x + i u_y`` of a die on one corner spinning at ``omega``
    about the vertical, its pivot slipping against a linear friction ``−slip_c·(pivot's velocity)`` (docs/model.md
    §12): ``I m s³ + ((I + m d²) c − i C m Ω) s² − (i C c Ω + m² g d) s − m g d c = 0`` with ``C = I`` (the isotropic
    inertia about the pivot–centre axis); for ``slip_c = inf`` the held pivot's
    ``(I + m d²) s² − i C Ω s − m g d = 0``."""
    m, g, c, w, I = float(mass), abs(float(g)), float(slip_c), float(omega), float(inertia)
    if math.isinf(c):
        return np.roots([I + m * d * d, -1j * I * w, -m * g * d])
    return np.roots([I * m, (I + m * d * d) * c - 1j * I * m * w, -(1j * I * c * w + m * m * g * d), -m * g * d * c])


def pivot_friction(cfg, omega: float) -> float:
    """The linear friction coefficient of the pivot of a die spinning at ``omega`` about the vertical through its
    corner: ``physical`` (per-node, viscous below v_reg): ``μ m g / v_reg``; ``seed`` (the spectral law
    ``μ P u/σ``, σ the spectral norm of all eight nodes' horizontal velocities): σ = 2√2·|Ω|·half, set by the
    spin, so ``μ m g/(2√2 |Ω| half)`` (inf at Ω = 0: the held pivot)."""
    p = cfg.preset
    m, g = 8.0, abs(float(p.g))
    if p.friction == "spectral":
        sig = 2.0 * math.sqrt(2.0) * abs(float(omega)) * float(p.half_side_cm)
        return float(p.mu) * m * g / sig if sig > 0 else math.inf
    return float(p.mu) * m * g / float(p.v_reg_cm_s)


def spinning_corner(omega: float, *, cfg=None, inertia: float | None = None, d: float | None = None,
                    slip_c: float | None = None, g: float = 980.0) -> SpinningCorner:
    """The linearisation of the corner balance spinning at ``omega`` about the vertical (:func:`spinning_roots`):
    the configuration's inertia, half diagonal and pivot friction (:func:`pivot_friction`), or those given.
    ValueError when no root is unstable (a sleeping top)."""
    if cfg is not None:
        p = cfg.preset
        inertia = float(p.inertia) if inertia is None else inertia
        d = math.sqrt(3.0) * float(p.half_side_cm) if d is None else d
        slip_c = pivot_friction(cfg, omega) if slip_c is None else slip_c
        g = abs(float(p.g))
    slip_c = math.inf if slip_c is None else slip_c
    w = abs(float(omega))
    lam0 = math.sqrt(8.0 * abs(g) * d / (inertia + 8.0 * d * d))

    def unstable(c):
        r = spinning_roots(w, inertia=inertia, d=d, slip_c=c, g=g)
        s = r[np.argmax(r.real)]
        if s.real <= 0:
            raise ValueError(f"no unstable root at spin {omega} rad/s")
        return complex(s)

    s, sh = unstable(slip_c), unstable(math.inf)
    return SpinningCorner(w, float(slip_c), lam0, s.real, s.imag, w - s.imag, (w - s.imag) * LN10 / s.real,
                          w * LN10 / s.real, s.imag * LN10 / s.real, (w - sh.imag) * LN10 / sh.real, sh.real, sh.imag)


def spinning_release(cfg, tilt: float, phi: float, *, spin: float, tilt_rate: float = 0.0, t_max_s: float | None = None,
                     record=None):
    """The die released off its corner balance (:func:`~dicetrace.analysis.corner.corner_release`) tilted by
    ``tilt`` toward ``phi`` and spinning at ``spin`` (rad/s) about the vertical, with ``tilt_rate`` (rad/s) toward
    ``phi + π/2`` besides (``seed``'s friction has no direction at rest: a release with some turning starts the
    adaptive integrators); the centre moves with the rigid rotation about the pivot below it, as there.  Returns
    the :class:`~dicetrace.simulate.Roll`."""
    from dicetrace.simulate import simulate

    from .corner import _release_config, corner_orientation

    c = _release_config(cfg, tilt, t_max_s)
    p = c.preset
    d = math.sqrt(3.0) * p.half_side_cm
    psi = phi + math.pi / 2
    omega = float(tilt_rate) * np.array([-math.sin(psi), math.cos(psi), 0.0]) + np.array([0.0, 0.0, float(spin)])
    ic = np.zeros(6)
    ic[:3] = np.cross(omega, [0.0, 0.0, d])
    sign = 1.0 if p.l_convention == "physical" else -1.0  # the program's L is the negative of the physical one
    ic[3:] = sign * p.inertia * omega
    return simulate(ic, config=c, orientation=corner_orientation(tilt, phi), record=record)


def release_borders(cfg, tilt: float, *, spin: float, tilt_ratio: float = 1.0, n_phi: int = 24,
                    tol: float = 1e-7) -> dict:
    """The faces on the ring of releases at ``tilt`` spinning at ``spin`` (:func:`spinning_release`, turning at
    ``tilt_ratio·λ₀·tilt`` besides) in ``n_phi`` directions, and the borders between them bisected in direction to
    ``tol`` (rad), as :func:`~dicetrace.analysis.corner_slice.circle_sectors` rows (``radius``: the tilt)."""
    from .corner import _bisect, corner_balance
    from .corner_slice import arcs

    lam0 = corner_balance(config=cfg).rate_rigid

    def face(ph):
        roll = spinning_release(cfg, tilt, float(ph), spin=spin, tilt_rate=tilt_ratio * lam0 * tilt)
        return int(roll.outcome) if roll.status.label == "settled" else -1

    ang = np.linspace(0.0, 2 * math.pi, int(n_phi), endpoint=False)
    lab = [face(a) for a in ang]
    runs = arcs(lab)
    borders = []
    evals = len(lab)
    if len(runs) > 1:
        for lb, s0, _ in runs:
            a, b = float(ang[s0 - 1]), float(ang[s0]) + (2 * math.pi if s0 == 0 else 0.0)
            a, b, la, lb, n = _bisect(face, a, b, lab[s0 - 1], lb, tol)
            evals += n
            borders.append({"angle": math.fmod(0.5 * (a + b), 2 * math.pi), "error": 0.5 * (b - a), "from": la,
                            "to": lb})
    faces = [r[0] for r in runs]
    return {"radius": float(tilt), "n": int(n_phi), "faces": faces, "n_arcs": len(runs), "borders": borders,
            "three_sectors": bool(len(runs) == 3 and len(set(faces)) == 3 and all(f > 0 for f in faces)),
            "evals": evals}


def border_tracks(circles: Sequence[dict], faces) -> tuple[np.ndarray, np.ndarray, list[tuple]]:
    """The border angles of the circles (:func:`~dicetrace.analysis.corner_slice.circle_sectors` rows) that show
    exactly three sectors of ``faces``: radii (m,), angles (m, 3) and the three borders' face pairs, the borders in
    counter-clockwise order on the first such circle.  Circles with other arcs are left out."""
    want = sorted(int(v) for v in faces)
    rows = [c for c in circles if c.get("three_sectors") and sorted(c["faces"]) == want and len(c["borders"]) == 3]
    if not rows:
        return np.zeros(0), np.zeros((0, 3)), []
    first = sorted(rows[0]["borders"], key=lambda b: b["angle"] % (2 * math.pi))
    pairs = [tuple(sorted((int(b["from"]), int(b["to"])))) for b in first]
    radii, ang = [], []
    for c in rows:
        by = {tuple(sorted((int(b["from"]), int(b["to"])))): float(b["angle"]) for b in c["borders"]}
        if set(by) != set(pairs):
            continue
        radii.append(float(c["radius"]))
        ang.append([by[p] for p in pairs])
    return np.array(radii), np.array(ang).reshape(-1, 3), pairs


def _wrap(x):
    return (np.asarray(x) + math.pi) % (2 * math.pi) - math.pi


def spiral_angles(radii, *, winding: float, q: float, gamma: float, phi0: float, n: int = 3,
                  scale: float = 1.0) -> np.ndarray:
    """Synthetic border angles (len(radii), n) of the spiral model of :func:`fit_spiral`: on each circle, the angles
    θ where ``arg(M z) + (winding/ln 10)·ln|M z|·sign(q) = phi0 + 2πk/n`` (mod 2π; ``q < 0`` reverses the order, as
    in the fit) for ``z = r e^{iθ}``, ``M = diag(1, q)·R(gamma)·scale``: a spiral turning counter-clockwise by
    ``winding`` per decade as r shrinks, for an undistorted map (``q = 1``).  Found on a fine ring of θ, interpolated
    linearly."""
    out = np.zeros((len(radii), n))
    c = -winding * math.copysign(1.0, q) / LN10  # the model's phase rate per e-fold (fit_spiral's w/ln 10)
    th = np.linspace(0.0, 2 * math.pi, 65537)
    for i, r in enumerate(radii):
        x, y = np.cos(th + gamma) * r * scale, q * np.sin(th + gamma) * r * scale
        phase = np.unwrap(np.arctan2(y, x) - c * np.log(np.hypot(x, y)))
        if phase[-1] < phase[0]:
            phase, sgn = -phase, -1.0
        else:
            sgn = 1.0
        for k in range(n):
            target = sgn * (phi0 + math.copysign(1.0, q) * 2 * math.pi * k / n)
            v = (phase - target) / (2 * math.pi)
            j = int(np.flatnonzero(np.floor(v[1:]) != np.floor(v[:-1]))[0])
            level = math.floor(v[j + 1]) * 2 * math.pi + target
            t = (level - phase[j]) / (phase[j + 1] - phase[j])
            out[i, k] = (th[j] + t * (th[j + 1] - th[j])) % (2 * math.pi)
    return out


@dataclasses.dataclass(frozen=True)
class SpiralFit:
    """The winding of three borders into a point (:func:`fit_spiral`).

    ``winding``/``stderr``: the model's turn per decade of radius (rad; its sign: counter-clockwise in the slice as
    the radius shrinks is positive), and its standard error; ``q``, ``gamma``, ``phi0``: the slice's linear distortion
    and the borders' phase; ``rms``: the residual (rad, in the model's phase); ``naive``: the mean of the three
    borders' straight-line slopes of the unwrapped angle against −log10 r (no distortion); ``n``: circles used."""

    winding: float
    stderr: float
    q: float
    gamma: float
    phi0: float
    rms: float
    naive: float
    naive_stderr: float
    n: int
    status: str

    def as_dict(self) -> dict:
        return {k: (v if not isinstance(v, float) or math.isfinite(v) else None)
                for k, v in dataclasses.asdict(self).items()}


def _naive(radii, ang) -> tuple[float, float]:
    x = -np.log10(radii)
    order = np.argsort(x)
    slopes = []
    for k in range(ang.shape[1]):
        a = np.unwrap(ang[order, k])
        slopes.append(np.polyfit(x[order], a, 1)[0] if len(x) > 1 else math.nan)
    s = np.array(slopes)
    return float(s.mean()), float(s.std(ddof=1) / math.sqrt(len(s))) if len(s) > 1 else math.nan


def fit_spiral(radii, angles) -> SpiralFit:
    """Fit the spiral model to border angles (radians; ``angles[i, k]``: border ``k`` on the circle of ``radii[i]``,
    the borders in the counter-clockwise order of :func:`border_tracks`).

    The model (module docstring): a point ``z = r e^{iθ}`` near the triple point leaves the balance with amplitude
    ``M z`` (``M`` linear: the slice's distortion, ``diag(1, q)·R(γ)`` up to a rotation and a scale that the phase
    absorbs), and the face is set by ``arg(M z) − (W/ln 10)·ln|M z|``, the borders at ``φ₀ + 2πk/3`` (the balance's
    three-fold symmetry); ``q < 0`` is a reflection, which reverses the borders' order.  Fitted by least squares of the
    phase residual (:func:`scipy.optimize.least_squares`, several starts); the standard error of ``W`` from the
    Jacobian, scaled by the residual.  Needs at least two circles."""
    r = np.asarray(radii, dtype=float)
    a = np.asarray(angles, dtype=float).reshape(len(r), -1)
    n = len(r)
    naive, naive_se = _naive(r, a) if n > 1 else (math.nan, math.nan)
    if n < 2:
        return SpiralFit(math.nan, math.nan, math.nan, math.nan, math.nan, math.nan, naive, naive_se, n, "too few")
    nb = a.shape[1]
    lr = np.log(r)[:, None]

    def resid(p, sign):
        w, lq, g, phi0 = p
        q = sign * math.exp(lq)
        x, y = np.cos(a + g), np.sin(a + g)  # R(γ) e^{iθ}
        zx, zy = x, q * y
        phase = np.arctan2(zy, zx) - w / LN10 * (lr + 0.5 * np.log(zx**2 + zy**2))
        k = np.arange(nb)[None, :] * (2 * math.pi / nb) * (1 if sign > 0 else -1)
        return _wrap(phase - phi0 - k).ravel()

    best = None
    w0 = naive if math.isfinite(naive) else 0.0
    for sign in (1.0, -1.0):
        for lq in (0.0, 1.0, -1.0, 2.5, -2.5):
            for g in np.linspace(0.0, math.pi, 4, endpoint=False):
                for ws in (w0, -w0):
                    p0 = np.array([ws, lq, g, 0.0])  # inside the bounds
                    p0[3] = float(np.angle(np.mean(np.exp(1j * (resid(p0, sign) + 0.0)))))
                    try:  # the squeeze bounded to 1e-6 … 1e6 (a fold of the phase beyond that is no fit)
                        res = optimize.least_squares(resid, p0, args=(sign,), method="trf",
                                                     bounds=([-np.inf, -LQ_MAX, -np.inf, -np.inf],
                                                             [np.inf, LQ_MAX, np.inf, np.inf]))
                    except (ValueError, np.linalg.LinAlgError, OverflowError, FloatingPointError):
                        continue
                    cost = float(np.sum(res.fun**2))
                    if best is None or cost < best[0] - 1e-15:
                        best = (cost, res, sign)
    if best is None:
        return SpiralFit(math.nan, math.nan, math.nan, math.nan, math.nan, math.nan, naive, naive_se, n, "no fit")
    cost, res, sign = best
    dof = max(res.fun.size - 4, 1)
    s2 = cost / dof
    try:
        cov = np.linalg.pinv(res.jac.T @ res.jac) * s2
        se = float(math.sqrt(max(cov[0, 0], 0.0)))
    except np.linalg.LinAlgError:
        se = math.nan
    w, lq, g, phi0 = res.x
    # the borders' turn in the slice, counter-clockwise positive as r shrinks: the phase holds while ln r falls, so
    # arg(M z) falls by w per decade; a reflection (q < 0) turns the slice's angle the other way
    turn = -w * sign
    return SpiralFit(float(turn), se, float(sign * math.exp(lq)), float(g % math.pi), float(phi0),
                     float(math.sqrt(cost / res.fun.size)), naive, naive_se, n, "ok" if res.success else res.message)


# --------------------------------------------------------------------------- 3. closest approach


def stretch_fit(r, dmin) -> dict:
    """``log10 D_min = log10 J + β log10 r`` by least squares over the rows (r > 0, D_min > 0): J, β and their
    standard errors, and the rows used."""
    r, d = np.asarray(r, float), np.asarray(dmin, float)
    ok = (r > 0) & (d > 0) & np.isfinite(r) & np.isfinite(d)
    if ok.sum() < 3 or np.ptp(np.log10(r[ok])) == 0:
        return {"J": math.nan, "beta": math.nan, "J_stderr": math.nan, "beta_stderr": math.nan, "n": int(ok.sum())}
    res = stats.linregress(np.log10(r[ok]), np.log10(d[ok]))
    return {"J": float(10**res.intercept), "beta": float(res.slope), "log10J_stderr": float(res.intercept_stderr),
            "beta_stderr": float(res.stderr), "n": int(ok.sum())}


def share_curve(dmin, D) -> dict:
    """Share of the throws (``dmin``: their closest approaches) with ``D_min < D`` at each ``D``: counts, shares and
    Poisson standard errors."""
    d = np.sort(np.asarray(dmin, float))
    D = np.asarray(D, float)
    k = np.searchsorted(d, D, side="left")
    n = len(d)
    return {"D": D.tolist(), "count": k.tolist(), "n": n, "share": (k / n).tolist(),
            "stderr": (np.sqrt(k) / n).tolist()}


def loglog_slope(D, counts, *, min_count: int = 5) -> dict:
    """The slope of ln(count) against ln D where ``count ≥ min_count`` (the cumulative counts of :func:`share_curve`),
    by maximum likelihood of the differential counts between neighbouring D under a power law ``share ∝ D^s`` (each
    bin's count Poisson), with its standard error from the likelihood's curvature."""
    D, c = np.asarray(D, float), np.asarray(counts, float)
    ok = c >= min_count
    if ok.sum() < 2:
        return {"slope": math.nan, "stderr": math.nan, "n_points": int(ok.sum()), "D_lo": math.nan, "D_hi": math.nan,
                "count": int(c[ok][-1]) if ok.any() else 0}
    Ds, cs = D[ok], c[ok]
    # bins: [0, D0), [D0, D1), ...; expected count in bin j: N (D_j^s − D_{j−1}^s)/D_top^s
    edges = np.concatenate([[0.0], Ds])
    counts = np.diff(np.concatenate([[0.0], cs]))
    total = cs[-1]

    def nll(s):
        e = np.diff(edges**s) / Ds[-1] ** s * total
        e = np.maximum(e, 1e-300)
        return float(np.sum(e - counts * np.log(e)))

    res = optimize.minimize_scalar(nll, bounds=(0.05, 40.0), method="bounded")
    s = float(res.x)
    h = 1e-4 * max(1.0, s)
    curv = (nll(s + h) - 2 * nll(s) + nll(s - h)) / h**2
    return {"slope": s, "stderr": float(1 / math.sqrt(curv)) if curv > 0 else math.nan, "n_points": int(ok.sum()),
            "D_lo": float(Ds[0]), "D_hi": float(Ds[-1]), "count": int(total)}


def predicted_share(D, J, beta, *, area: float = 1.0) -> np.ndarray:
    """``Σ_i π (D/J_i)^(2/β_i) / area`` at each D: the area where ``J_i r^β_i < D`` about each point, summed (points
    with a non-finite or non-positive J or β are left out)."""
    D = np.asarray(D, float)
    out = np.zeros_like(D)
    for j, b in zip(np.asarray(J, float), np.asarray(beta, float)):
        if np.isfinite(j) and np.isfinite(b) and j > 0 and b > 0:
            out += math.pi * (D / j) ** (2.0 / b)
    return out / area
