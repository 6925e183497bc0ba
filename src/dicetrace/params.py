"""Validated, frozen configuration: the model preset and the numerics.

Bottom layers of dicetrace (it imports only the integrator table and the
status enum).  Units are the
2019 program's: centimetres, seconds and "node mass" (each of the die's eight
corner nodes has mass 1, the die 8).  Force is node-mass·cm/s².

``Preset`` is the physical model, ``Numerics`` how it is integrated; both
convert themselves into :class:`KernelParams`, the plain ``NamedTuple`` of
parameters that the numba kernels take (:meth:`Config.kernel_inputs` turns
ICs into everything a kernel needs).
"""

from __future__ import annotations

import functools
import math
import warnings
from dataclasses import asdict, dataclass, field, fields, replace
from typing import NamedTuple

import numpy as np

from dicetrace.config_values import ConfigError  # noqa: F401  (re-exported)
from dicetrace.config_values import is_number as _is_number, plain as _plain, read_number as _read_number, show as _show
from dicetrace.body import Body
from dicetrace.integrators import INTEGRATORS, IntegratorSpec, get_integrator, unknown_integrator  # noqa: F401  (re-exported)
from dicetrace.stepsize import auto_dt

#: The impact speed at which a preset's ``restitution`` is the coefficient of restitution of the die's flat drop, cm/s.
RESTITUTION_SPEED_CM_S = 100.0


@functools.lru_cache(maxsize=256)
def _gamma_for_flat_drop(e: float, v: float, k: float, g: float) -> float:
    """γ for restitution ``e`` of the die's flat drop (4 nodes, mass 8) at impact speed ``v`` (``dicetrace.materials``)."""
    from dicetrace.materials import gamma_for_restitution

    return gamma_for_restitution(e, v, k, g=g, n_contact=4, mass=8.0)


#: Default friction regularisation speed of the per-node law, cm/s (see Preset).
V_REG_CM_S = 10.0

FRICTION_SPECTRAL = 0  # the program: −μ·P_k·u_xy,k / σ(all nodes' u_xy)
FRICTION_PER_NODE = 1  # physical: −μ·max(P_k,0)·u_xy,k / sqrt(|u_xy,k|² + v_reg²)

ENERGY_POINT_MASS = 0  # the program's stop-test energy (point-mass kinetic energy)
ENERGY_RIGID = 1  # kinetic energy with the inertia the dynamics use

#: Conventions for the sign of an IC's angular momentum L.
L_CONVENTIONS = ("program", "physical")
#: The convention the kernels work in (the 2019 program's: −physical L).
KERNEL_L_CONVENTION = "program"

#: Body-frame node offsets in units of the half side (``dicetrace.body``, where the die's geometry is written once).
from dicetrace.body import NODE_SIGNS  # noqa: E402,F401  (re-exported)


def convert_l(ics, from_convention: str, to_convention: str) -> np.ndarray:
    """ICs (..., 6) from one L sign convention to another (L negated when they differ).

    The one place where dicetrace flips L.  Returns the input itself when
    the conventions agree, else a new float64 array.
    """
    for c in (from_convention, to_convention):
        if c not in L_CONVENTIONS:
            raise ValueError(f"L convention must be one of {', '.join(L_CONVENTIONS)}, got {c!r}")
    if from_convention == to_convention:
        return ics
    out = np.array(ics, dtype=np.float64, copy=True)
    out[..., 3:] = -out[..., 3:]
    return out


class KernelInputs(NamedTuple):
    """What a kernel takes besides its output buffers (see :meth:`Config.kernel_inputs`)."""

    ics: np.ndarray  # (m, 6) or (6,) float64, C-contiguous, kernel (program) L convention
    off0: np.ndarray  # (8, 3) initial node offsets, cm
    params: "KernelParams"
    integrator_id: int


class KernelParams(NamedTuple):
    """Flat parameters for the numba kernels (field order is the ABI).

    Built only by :meth:`Config.kernel_params`; mode fields are compared with
    the named constants above, never with literals.
    """

    k: float  # ground stiffness per node mass, 1/s² (Preset.k)
    gamma: float  # damping coefficient, s/cm (Preset.gamma)
    mu: float  # friction coefficient (Preset.mu)
    g: float  # gravity along z, cm/s², negative (Preset.g)
    half_side_cm: float  # half side of the cube, cm (Preset.half_side_cm)
    inertia: float  # isotropic moment of inertia, node-mass·cm² (Preset.inertia)
    z0_cm: float  # initial height of the centre of mass, cm (Preset.z0_cm)
    dt_s: float  # time step, s (Numerics.dt_s)
    max_steps: float  # time cap as a number of steps (Numerics.max_steps)
    e_stop: float  # stop-test threshold, node-mass·cm²/s² above e_rest (Preset.e_stop)
    e_rest: float  # energy of the die lying on a face, node-mass·cm²/s² (Preset.e_rest)
    friction_mode: int  # FRICTION_SPECTRAL or FRICTION_PER_NODE (Preset.friction)
    clamp_normal: bool  # True: normal force clamped at zero; False: signed, the program (Preset.clamp_normal)
    energy_mode: int  # ENERGY_POINT_MASS or ENERGY_RIGID (Preset.energy)
    v_reg_cm_s: float  # friction regularisation speed, cm/s, per-node law (Preset.v_reg_cm_s)
    blowup_rel: float  # blow-up if E_dyn - E_rest > (1+rel)·(E0 - E_rest) + abs
    blowup_abs: float
    substeps: float  # sub-steps per step while in contact (contact-substep)
    tol: float = 0.0  # local error tolerance of the sub-steps (the adaptive integrators); 0: fixed sub-steps
    tol_growth: float = 0.0  # 1/s: the tolerance at time t is tol·exp(tol_growth·t), at most TOL_LOOSEST (Numerics)
    # The body (dicetrace.body; the cube: isotropic, and these give the cube's own numbers):
    isotropic: bool = True  # a uniform cube: ω = L / inertia, free flight exact; else the fields below
    reach_cm: float = 1.7320508075688772  # the nodes' largest distance from the centre of mass, cm
    inv_mass_node: float = 0.6875  # a node's largest inverse effective mass along the ground, 1/node-mass
    ii_xx: float = 0.1875  # the inverse inertia tensor in the body frame, 1/(node-mass·cm²)
    ii_yy: float = 0.1875
    ii_zz: float = 0.1875
    ii_xy: float = 0.0
    ii_xz: float = 0.0
    ii_yz: float = 0.0
    rh_x: float = 0.125  # 1/(8·half-extent) along each body axis: R's columns from the node offsets
    rh_y: float = 0.125
    rh_z: float = 0.125
    com_x: float = 0.0  # the centre of mass in the body frame, from the box's centre, cm
    com_y: float = 0.0
    com_z: float = 0.0
    e_rest1: float = 7840.0  # the energy of the die resting on face 1..6 (centre of mass height), node-mass·cm²/s²
    e_rest2: float = 7840.0
    e_rest3: float = 7840.0
    e_rest4: float = 7840.0
    e_rest5: float = 7840.0
    e_rest6: float = 7840.0
    e_stop1: float = 2597.9474632040528  # the stop threshold above it on face 1..6 (80 % of its tip barrier)
    e_stop2: float = 2597.9474632040528
    e_stop3: float = 2597.9474632040528
    e_stop4: float = 2597.9474632040528
    e_stop5: float = 2597.9474632040528
    e_stop6: float = 2597.9474632040528


#: Smallest ``Numerics.tol``: below it the error estimate is rounding.
TOL_MIN = 1e-14
#: The loosest tolerance ``Numerics.tol_growth`` lets the tolerance reach.  Late in a
#: throw the die rests or rocks on its springs, which Tsit5 lets ring at the level of
#: the tolerance: at 1e-5 a die on a face sits at its equilibrium penetration to 1.5 %
#: and vibrates at ~0.02 cm/s; at 1e-4 15 % and 0.15 cm/s, with its energy rising.
TOL_LOOSEST = 1e-5
#: Largest ``Numerics.tol_growth``, 1/s (a hundred times the die's Lyapunov exponent).
TOL_GROWTH_MAX = 1000.0


def _valid_tol(v) -> bool:
    """An error tolerance: a finite number in [TOL_MIN, 1) (``Numerics.tol``, ``Preset.default_tol``)."""
    return _is_number(v) and math.isfinite(v) and TOL_MIN <= v < 1


def _spec(integrator) -> IntegratorSpec:
    """The integrator named ``integrator``, or ConfigError naming the field."""
    try:
        return get_integrator(integrator)
    except ValueError as e:
        raise ConfigError("integrator", str(e)) from None


def _valid_positive(v) -> bool:
    """A time step or time cap, s: a finite number > 0 (``Numerics.dt_s``, ``Numerics.t_max_s``)."""
    return _is_number(v) and math.isfinite(v) and v > 0


def _valid_tol_growth(v) -> bool:
    """A tolerance growth rate, 1/s: a finite number in [0, TOL_GROWTH_MAX] (``Numerics.tol_growth``, ``Preset.default_tol_growth``)."""
    return _is_number(v) and math.isfinite(v) and 0 <= v <= TOL_GROWTH_MAX


@dataclass(frozen=True)
class Preset:
    """A physical model of the die and the ground.

    Parameters
    ----------
    name
        Preset name (``"seed"`` or ``"physical"``, or a user's name).
    k
        Ground stiffness per node mass, 1/s² (the writeup's 500000 N/cm with
        node mass 1).
    gamma
        Damping coefficient, s/cm.
    mu
        Coulomb friction coefficient.
    g
        Gravity along z, cm/s² (negative: down).
    half_side_cm
        Half the cube's side, cm.
    z0_cm
        Initial height of the centre of mass, cm.
    friction
        ``"spectral"`` (the program: every node's friction is scaled by the
        spectral norm of all eight horizontal velocities) or ``"per-node"``.
    clamp_normal
        Clamp the normal force at zero (no pulling ground).
    energy
        ``"point-mass"`` (the program's stop-test energy) or ``"rigid"``.
    v_reg_cm_s
        Friction regularisation speed for ``"per-node"`` friction, cm/s:
        F_xy = −μ·P·u_xy / sqrt(|u_xy|² + v_reg²), Coulomb's law above a few
        v_reg, viscous below.  Default 10 cm/s (:data:`V_REG_CM_S`): impact
        slip speeds are 10²–10³ cm/s, so friction there is ≥ 98 % of
        Coulomb's; at 1 cm/s the law is so stiff while a corner sticks that
        outcomes do not converge at any affordable step (analysis/accuracy).
    l_convention
        ``"program"``: an IC's L is the program's (−physical) angular momentum;
        ``"physical"``: it is the physical one.
    integrator
        The integrator used when none is named (``seed``: the program's
        semi-implicit Euler; ``physical``: ``contact-tsit5``, because its
        per-node friction is too stiff for an explicit 1 ms step — semi-implicit
        Euler blows up on a third of throws there — error-controlled sub-steps
        reach 0.8–1.0 outcome agreement 1.5–3× cheaper than fixed ones, and at
        the default tolerance Tsitouras' 5(4) pair is the cheapest of the
        error-controlled schemes that reaches 0.93 outcome agreement with the
        converged reference (0.98; see analysis/accuracy).
    half_extents_cm
        The die's box: its three half-extents along the body axes x, y, z, cm
        (``dicetrace.body``); None (the default): the cube of ``half_side_cm``.
        A box that is no cube needs a contact integrator with a continuous
        method (``contact-tsit5``, ``contact-dop853``) and the ``rigid``
        energy.
    load_fraction, load_cm
        A loaded die: the share of its mass (in [0, 1)) in a point load at
        ``load_cm`` (cm, body frame, from the box's centre, inside the box).
        0 (the default): uniform.
    restitution, restitution_speed_cm_s
        The coefficient of restitution e of the die's flat drop at the impact
        speed ``restitution_speed_cm_s`` (default 100 cm/s): when given, it
        sets ``gamma`` (the one γ of the ground law that gives it, with this
        k and g; ``dicetrace.materials.gamma_for_restitution``, docs/model.md
        §13).  None (the default): ``gamma`` as given.
    default_tol, default_tol_growth
        The error tolerance and its growth rate (``Numerics.tol``,
        ``Numerics.tol_growth``) that an error-controlled integrator uses on
        this preset when the caller gives neither (one given: the other keeps
        its ``Numerics`` default).  None (``seed``): ``Numerics``' defaults,
        a uniform 1e-7.  ``physical``: 2e-8 loosening at 10 /s (up to
        :data:`TOL_LOOSEST`): the same outcome agreement with the converged
        reference as a uniform 1e-7 within the sample's noise (0.96 against
        0.97), with 0.7x the sub-step attempts (analysis/accuracy/TUNING.md §9).
    """

    name: str = "seed"
    k: float = 500000.0
    gamma: float = 0.005
    mu: float = 1.2
    g: float = -980.0
    half_side_cm: float = 1.0
    z0_cm: float = 15.0
    friction: str = "spectral"
    clamp_normal: bool = False
    energy: str = "point-mass"
    v_reg_cm_s: float = V_REG_CM_S
    l_convention: str = "program"
    integrator: str = "semi-implicit-euler"
    default_tol: float | None = None
    default_tol_growth: float = 0.0
    half_extents_cm: tuple[float, float, float] | None = None
    load_fraction: float = 0.0
    load_cm: tuple[float, float, float] = (0.0, 0.0, 0.0)
    restitution: float | None = None
    restitution_speed_cm_s: float = RESTITUTION_SPEED_CM_S

    def __post_init__(self) -> None:
        if not isinstance(self.name, str):
            raise ConfigError("name", f"preset name must be a string, got {_show(self.name)}")
        for name in ("k", "gamma", "mu", "g", "half_side_cm", "z0_cm", "v_reg_cm_s"):
            v = getattr(self, name)
            if not _is_number(v) or not math.isfinite(v):
                raise ConfigError(name, f"preset {self.name!r}: {name} must be a finite number, got {_show(v)}")
            object.__setattr__(self, name, _plain(v))
        if self.k <= 0:
            raise ConfigError("k", f"preset {self.name!r}: stiffness k must be > 0, got {self.k!r}")
        if self.gamma < 0:
            raise ConfigError("gamma", f"preset {self.name!r}: damping gamma must be >= 0, got {self.gamma!r}")
        if self.mu < 0:
            raise ConfigError("mu", f"preset {self.name!r}: friction coefficient mu must be >= 0, got {self.mu!r}")
        if self.g > 0:
            raise ConfigError(
                "g", f"preset {self.name!r}: gravity g must be <= 0 (cm/s² along z; negative points down, the default is "
                f"-980; positive would lift the die away from the ground), got {self.g!r}"
            )
        if self.restitution is not None:  # the damping that gives it (k and g checked above)
            object.__setattr__(self, "gamma", self._gamma_of_restitution())
        if self.half_side_cm <= 0:
            raise ConfigError("half_side_cm", f"preset {self.name!r}: half_side_cm must be > 0, got {self.half_side_cm!r}")
        if self.half_extents_cm is None and self.load_fraction == 0 and self.z0_cm < self.half_side_cm:
            raise ConfigError(
                "z0_cm", f"preset {self.name!r}: z0_cm (the start height of the centre) must be >= half_side_cm "
                f"({self.half_side_cm!r}: the die starts on or above the ground), got {self.z0_cm!r}"
            )
        if self.v_reg_cm_s <= 0:
            raise ConfigError("v_reg_cm_s", f"preset {self.name!r}: v_reg_cm_s must be > 0, got {self.v_reg_cm_s!r}")
        if not isinstance(self.clamp_normal, (bool, np.bool_)):
            raise ConfigError("clamp_normal", f"preset {self.name!r}: clamp_normal must be True or False, got {_show(self.clamp_normal)}")
        object.__setattr__(self, "clamp_normal", bool(self.clamp_normal))
        if self.friction not in ("spectral", "per-node"):
            raise ConfigError("friction", f"preset {self.name!r}: friction must be 'spectral' or 'per-node', got {self.friction!r}")
        if self.energy not in ("point-mass", "rigid"):
            raise ConfigError("energy", f"preset {self.name!r}: energy must be 'point-mass' or 'rigid', got {self.energy!r}")
        if self.l_convention not in L_CONVENTIONS:
            raise ConfigError("l_convention", f"preset {self.name!r}: l_convention must be 'program' or 'physical'")
        if self.integrator not in INTEGRATORS:
            raise ConfigError("integrator", f"preset {self.name!r}: {unknown_integrator(self.integrator)}")
        tol = self.default_tol
        if tol is not None:
            if not _valid_tol(tol):
                raise ConfigError("default_tol", f"preset {self.name!r}: default_tol must be None or a number in [{TOL_MIN:g}, 1), "
                                 f"got {_show(tol)}")
            object.__setattr__(self, "default_tol", _plain(tol))
        gr = self.default_tol_growth
        if not _valid_tol_growth(gr):
            raise ConfigError("default_tol_growth", f"preset {self.name!r}: default_tol_growth must be a number in [0, {TOL_GROWTH_MAX:g}] "
                             f"(1/s), got {_show(gr)}")
        object.__setattr__(self, "default_tol_growth", _plain(gr))
        self._check_body()

    def _check_body(self) -> None:
        """The box and the load, checked (``dicetrace.body.Body``); a cube of half_side_cm stored as None."""
        h = self.half_extents_cm
        if h is not None:
            try:
                h = tuple(_plain(v) for v in h)
            except TypeError:
                raise ConfigError("half_extents_cm", f"preset {self.name!r}: half_extents_cm must be three numbers "
                                  f"(cm), got {_show(self.half_extents_cm)}") from None
        try:
            load = tuple(_plain(v) for v in self.load_cm)
        except TypeError:
            raise ConfigError("load_cm", f"preset {self.name!r}: load_cm must be three numbers (cm), got "
                              f"{_show(self.load_cm)}") from None
        for name, v in (("half_extents_cm", h), ("load_cm", load)):
            if v is not None and (len(v) != 3 or not all(_is_number(x) and math.isfinite(x) for x in v)):
                raise ConfigError(name, f"preset {self.name!r}: {name} must be three finite numbers (cm), got {_show(v)}")
        w = self.load_fraction
        if not _is_number(w) or not math.isfinite(w) or not 0 <= w < 1:
            raise ConfigError("load_fraction", f"preset {self.name!r}: load_fraction must be a number in [0, 1), got "
                              f"{_show(w)}")
        try:
            body = Body(h if h is not None else (self.half_side_cm,) * 3, w, load)
        except ValueError as e:
            raise ConfigError("half_extents_cm" if "half_extents" in str(e) else "load_cm",
                              f"preset {self.name!r}: {e}") from None
        if self.z0_cm < body.face_heights_cm[2]:
            raise ConfigError("z0_cm", f"preset {self.name!r}: z0_cm (the start height of the centre of mass) must be "
                              f">= {body.face_heights_cm[2]:g}, its height resting on face 3 (the die starts on or "
                              f"above the ground), got {self.z0_cm!r}")
        object.__setattr__(self, "half_extents_cm", h)
        object.__setattr__(self, "load_fraction", _plain(w))
        object.__setattr__(self, "load_cm", load)

    def _gamma_of_restitution(self) -> float:
        """γ that gives the die's flat drop the coefficient of restitution ``restitution`` at ``restitution_speed_cm_s``."""
        e, v = self.restitution, self.restitution_speed_cm_s
        if not _is_number(e) or not 0.0 < e <= 1.0:
            raise ConfigError("restitution", f"preset {self.name!r}: restitution must be None or a number in (0, 1], "
                              f"got {_show(e)}")
        if not _is_number(v) or not (math.isfinite(v) and v > 0):
            raise ConfigError("restitution_speed_cm_s", f"preset {self.name!r}: restitution_speed_cm_s must be a finite "
                              f"number > 0, got {_show(v)}")
        object.__setattr__(self, "restitution", _plain(e))
        object.__setattr__(self, "restitution_speed_cm_s", _plain(v))
        return _gamma_for_flat_drop(self.restitution, self.restitution_speed_cm_s, self.k, self.g)

    @property
    def body(self) -> Body:
        """The die's body (``dicetrace.body``): the box (the cube of ``half_side_cm`` unless ``half_extents_cm``) and
        its load."""
        h = self.half_extents_cm if self.half_extents_cm is not None else (self.half_side_cm,) * 3
        return Body(h, self.load_fraction, self.load_cm)

    @property
    def is_cube(self) -> bool:
        """A uniform cube (what every integrator runs; a box or a loaded die needs a continuous contact scheme)."""
        return self.body.is_cube

    @property
    def node_mass(self) -> float:
        return 1.0

    @property
    def inertia(self) -> float:
        """Isotropic moment of inertia (1/6)·M·s² with M = 8, s = side, node-mass·cm²; of a die that is no uniform
        cube, its smallest principal moment (a scale of the error norms)."""
        if not self.is_cube:
            return float(np.linalg.eigvalsh(self.body.inertia)[0])
        side = 2.0 * self.half_side_cm
        return 8.0 * side * side / 6.0

    @property
    def e_rest(self) -> float:
        """Gravitational energy of the die lying on a face, Σ m·|g|·z = 8·|g|·half; of a die that is no uniform
        cube, on its lowest face (the blow-up test's reference)."""
        if not self.is_cube:
            return float(8.0 * (-self.g) * self.body.face_heights_cm.min())
        return 8.0 * (-self.g) * self.half_side_cm

    @property
    def e_stop(self) -> float:
        """Stop-test threshold: 80 % of the energy to stand the die on an edge.

        The program writes it as 0.8·(8·|g|·(√2 − 1)) for a unit half side.  A
        die that is no uniform cube has one per face (:meth:`face_energies`);
        this is their least.
        """
        if not self.is_cube:
            return float(self.face_energies()[1].min())
        return 0.8 * self.e_rest * (math.sqrt(2.0) - 1.0)

    def face_energies(self) -> tuple[np.ndarray, np.ndarray]:
        """Per face (6,): the energy of the die resting on it, 8·|g|·(its centre's height), and the stop threshold
        above it, 80 % of the energy to tip it onto its nearest edge (the cube's: ``e_rest``, ``e_stop``)."""
        b = self.body
        mg = 8.0 * (-self.g)
        return mg * b.face_heights_cm, 0.8 * mg * b.tip_barriers_cm

    def with_(self, **changes) -> "Preset":
        return replace(self, **changes)


PRESETS: dict[str, Preset] = {
    "seed": Preset(name="seed"),
    # The program's slips corrected (docs/model.md §7): normal force clamped
    # at zero, Coulomb friction per node on that clamped force (regularised
    # by v_reg), energy with the dynamics' inertia, physical sign of L.
    "physical": Preset(
        name="physical",
        friction="per-node",
        clamp_normal=True,
        energy="rigid",
        v_reg_cm_s=V_REG_CM_S,
        l_convention="physical",
        integrator="contact-tsit5",
        default_tol=2e-8,
        default_tol_growth=10.0,
    ),
}


def get_preset(name: str) -> Preset:
    try:
        return PRESETS[name]
    except KeyError:
        raise ConfigError("preset", f"unknown preset {name!r} (choose from {', '.join(PRESETS)})") from None


@dataclass(frozen=True)
class Numerics:
    """How a preset is integrated.

    Parameters
    ----------
    integrator
        One of :data:`INTEGRATORS`.
    dt_s
        Time step, s (> 0).
    t_max_s
        Time cap, s of simulated time; a run that has not settled by then ends
        with status ``time_cap`` and no outcome.
    substeps
        ``contact-substep`` only: near the ground its RK4 sub-steps are at
        most dt / substeps long (shorter where the friction law is stiff, and
        cut where a node enters or leaves the ground).  dt itself then sets
        only the free-flight step and the output granularity (contact sets,
        stop test, settle time).
    tol
        The error-controlled integrators only (``contact-adaptive``,
        ``contact-dop853``, ``contact-tsit5``:
        ``IntegratorSpec.adaptive``): the local error
        tolerance of their sub-steps (relative: position error per sub-step in
        units of the half side, velocity error in units of the die's current
        speed |U| + √3·half·|ω| + √(|g|·half)), in [``TOL_MIN``, 1).  Their
        sub-steps are at most dt long (``contact-tsit5``, whose step ends are interpolated: 2·dt).
    tol_growth
        The error-controlled integrators only: a rate, 1/s, at which their
        tolerance loosens over a throw.  At time t after the start the
        tolerance is ``tol·exp(tol_growth·t)``, never looser than
        :data:`TOL_LOOSEST` (nor looser than ``tol`` itself when that is
        looser).  0 (the default): the same tolerance throughout.  A local
        error made at time t reaches the outcome amplified by about
        exp(λ·(T − t)), λ the die's Lyapunov exponent (12–15 /s): late errors
        matter less, and a rate near 5λ/6 spends the error budget where it
        buys the outcome (docs/model.md §9).  In [0, ``TOL_GROWTH_MAX``].
    """

    integrator: str = "semi-implicit-euler"
    dt_s: float = 0.001
    t_max_s: float = 60.0
    substeps: int = 8
    tol: float = 1e-7
    tol_growth: float = 0.0

    def __post_init__(self) -> None:
        _spec(self.integrator)
        for name, what in (("dt_s", "time step dt"), ("t_max_s", "time cap t_max")):
            v = getattr(self, name)
            if not _valid_positive(v):
                raise ConfigError(name, f"{what} must be a finite number > 0, got {_show(v)}")
            object.__setattr__(self, name, _plain(v))
        if self.dt_s > self.t_max_s:
            raise ConfigError(("t_max_s", "dt_s"), f"time step dt ({self.dt_s!r} s) is longer than the time cap t_max "
                              f"({self.t_max_s!r} s): not even one step fits")
        if self.t_max_s / self.dt_s > 2**40:
            raise ConfigError(("t_max_s", "dt_s"), f"time cap / dt is too large: t_max {self.t_max_s!r} s / dt "
                              f"{self.dt_s!r} s = {self.t_max_s / self.dt_s:.3g} steps (at most 2**40)")
        sub = self.substeps
        if not _is_number(sub) or not math.isfinite(sub) or int(sub) != sub or sub < 1:
            raise ConfigError("substeps", f"substeps must be an integer >= 1, got {_show(sub)}")
        object.__setattr__(self, "substeps", _plain(sub))
        if not _valid_tol(self.tol):
            raise ConfigError("tol", f"tolerance tol must be a number in [{TOL_MIN:g}, 1), got {_show(self.tol)}")
        if not _valid_tol_growth(self.tol_growth):
            raise ConfigError("tol_growth", f"tolerance growth tol_growth must be a number in [0, {TOL_GROWTH_MAX:g}] "
                              f"(1/s), got {_show(self.tol_growth)}")
        object.__setattr__(self, "tol", _plain(self.tol))
        object.__setattr__(self, "tol_growth", _plain(self.tol_growth))

    @property
    def max_steps(self) -> int:
        return int(math.ceil(self.t_max_s / self.dt_s - 1e-9))

    @property
    def spec(self) -> IntegratorSpec:
        """The integrator's :class:`IntegratorSpec`."""
        return INTEGRATORS[self.integrator]

    @property
    def integrator_id(self) -> int:
        return self.spec.kernel_id

    @property
    def order(self) -> int:
        return self.spec.order


#: The schemes that integrate a body that is no uniform cube (ω = I⁻¹·L along the flow, precession in flight):
#: the contact driver on an embedded Runge–Kutta pair with a quaternion (``core.methods.erk``).
BODY_SCHEMES = ("contact_tsit5", "contact_dop853")
BODY_INTEGRATORS = tuple(n for n, sp in INTEGRATORS.items() if sp.scheme in BODY_SCHEMES)


def _body_scale(body: Body) -> float:
    """A die's length scale for the error norms and the free-flight bounds: its reach over √3 (the cube: its half
    side)."""
    return body.reach_cm / math.sqrt(3.0)


def _body_params(p: "Preset") -> dict:
    """The body's fields of :class:`KernelParams`: the cube's own numbers for a uniform cube (its kernels then use
    the scalar inertia as before), else the box's (``dicetrace.body``)."""
    if p.is_cube:
        h = float(p.half_side_cm)
        inertia = p.inertia
        # a node's inverse effective mass along the ground: at most 1/8 + |r|²/I = 1/8 + 3h²/(16h²/3) = 11/16
        return dict(isotropic=True, reach_cm=math.sqrt(3.0) * h, inv_mass_node=11.0 / 16.0,
                    ii_xx=1.0 / inertia, ii_yy=1.0 / inertia, ii_zz=1.0 / inertia, ii_xy=0.0, ii_xz=0.0, ii_yz=0.0,
                    rh_x=1.0 / (8.0 * h), rh_y=1.0 / (8.0 * h), rh_z=1.0 / (8.0 * h),
                    **{f"e_rest{f}": float(p.e_rest) for f in range(1, 7)},
                    **{f"e_stop{f}": float(p.e_stop) for f in range(1, 7)})
    b = p.body
    ii = np.linalg.inv(b.inertia)
    rest, stop = p.face_energies()
    h = b.half_extents_cm
    return dict(isotropic=False, reach_cm=b.reach_cm, inv_mass_node=b.inv_mass_node,
                ii_xx=float(ii[0, 0]), ii_yy=float(ii[1, 1]), ii_zz=float(ii[2, 2]), ii_xy=float(ii[0, 1]),
                ii_xz=float(ii[0, 2]), ii_yz=float(ii[1, 2]),
                rh_x=1.0 / (8.0 * h[0]), rh_y=1.0 / (8.0 * h[1]), rh_z=1.0 / (8.0 * h[2]),
                com_x=float(b.com_cm[0]), com_y=float(b.com_cm[1]), com_z=float(b.com_cm[2]),
                **{f"e_rest{f}": float(rest[f - 1]) for f in range(1, 7)},
                **{f"e_stop{f}": float(stop[f - 1]) for f in range(1, 7)})


# Blow-up test on the energy the dynamics conserve (see core.model.energy_dynamic):
# a run whose energy above the resting level exceeds (1 + BLOWUP_REL) times its
# initial value plus BLOWUP_ABS has blown up.
BLOWUP_REL = 0.25
BLOWUP_ABS_FRACTION = 0.1  # of the resting energy 8·|g|·half


@dataclass(frozen=True)
class Config:
    """A preset with its numerics: everything a kernel needs but the IC."""

    preset: Preset = field(default_factory=lambda: PRESETS["seed"])
    numerics: Numerics = field(default_factory=Numerics)

    def __post_init__(self) -> None:
        p, spec = self.preset, self.numerics.spec
        if not p.is_cube:
            if spec.scheme not in BODY_SCHEMES:
                raise ConfigError("integrator", f"preset {p.name!r} is no uniform cube (a box or a loaded die): it needs "
                                  f"an integrator that follows its precession, {' or '.join(BODY_INTEGRATORS)}, not "
                                  f"{spec.name!r}")
            if p.energy != "rigid":
                raise ConfigError("energy", f"preset {p.name!r} is no uniform cube: its stop test needs the rigid "
                                  f"energy (energy='rigid'), not {p.energy!r}")

    def kernel_params(self) -> KernelParams:
        p, n = self.preset, self.numerics
        return KernelParams(
            k=float(p.k),
            gamma=float(p.gamma),
            mu=float(p.mu),
            g=float(p.g),
            half_side_cm=float(p.half_side_cm) if p.is_cube else _body_scale(p.body),
            inertia=float(p.inertia),
            z0_cm=float(p.z0_cm),
            dt_s=float(n.dt_s),
            max_steps=float(n.max_steps),
            e_stop=float(p.e_stop),
            e_rest=float(p.e_rest),
            friction_mode=FRICTION_SPECTRAL if p.friction == "spectral" else FRICTION_PER_NODE,
            clamp_normal=bool(p.clamp_normal),
            energy_mode=ENERGY_POINT_MASS if p.energy == "point-mass" else ENERGY_RIGID,
            v_reg_cm_s=float(p.v_reg_cm_s),
            blowup_rel=BLOWUP_REL,
            blowup_abs=BLOWUP_ABS_FRACTION * p.e_rest,
            substeps=1.0 if n.spec.adaptive else float(n.substeps),
            tol=float(n.tol) if n.spec.adaptive else 0.0,
            tol_growth=float(n.tol_growth) if n.spec.adaptive else 0.0,
            **_body_params(p),
        )

    def initial_offsets(self, orientation=None) -> np.ndarray:
        """Initial node offsets (8, 3), cm: ±half on each axis (a box's or loaded die's corners from its centre of
        mass, ``body.Body.node_offsets_cm``), turned by ``orientation``.

        ``orientation`` is a world-from-body rotation matrix (3, 3), or None
        for the program's start (face 3 down, face 4 up).
        """
        p = self.preset
        off = NODE_SIGNS * p.half_side_cm if p.is_cube else p.body.node_offsets_cm
        if orientation is None:
            return np.ascontiguousarray(off)
        rot = np.asarray(orientation, dtype=np.float64)
        if rot.shape != (3, 3) or not np.all(np.isfinite(rot)):
            raise ValueError("orientation must be a finite 3×3 rotation matrix")
        if np.abs(rot @ rot.T - np.eye(3)).max() > 1e-9 or np.linalg.det(rot) < 0:
            raise ValueError("orientation is not a rotation matrix (RᵀR ≠ I or det < 0)")
        return np.ascontiguousarray(off @ rot.T)

    def kernel_inputs(self, ics, *, l_convention: str | None = None, orientation=None) -> KernelInputs:
        """Turn validated ICs into kernel inputs: the one door from ICs to a kernel.

        ``ics`` (m, 6) or (6,) are in ``l_convention`` (default: the preset's);
        the kernels take L in the program's convention.  Also the initial
        offsets (:meth:`initial_offsets`), the :class:`KernelParams` and the
        integrator's kernel id.
        """
        conv = self.preset.l_convention if l_convention is None else l_convention
        # writeable too: numba types a read-only array (pandas 3's views) apart and would compile the kernels again
        kics = np.require(convert_l(ics, conv, KERNEL_L_CONVENTION), dtype=np.float64, requirements=["C", "W"])
        return KernelInputs(kics, self.initial_offsets(orientation), self.kernel_params(), self.numerics.integrator_id)

    def to_preset_convention(self, ics, l_convention: str) -> np.ndarray:
        """ICs given in ``l_convention`` expressed in this preset's convention."""
        return convert_l(ics, l_convention, self.preset.l_convention)

    def as_dict(self) -> dict:
        """Plain dict of every parameter (stored in file metadata)."""
        return {"preset": asdict(self.preset), "numerics": asdict(self.numerics)}


def make_config(
    preset: str | Preset = "seed",
    *,
    integrator: str | None = None,
    dt_s: float | str | None = None,
    t_max_s: float | str | None = None,
    v_impact_cm_s: float | None = None,
    tol: float | str | None = None,
    tol_growth: float | str | None = None,
    strict: bool = False,
    **overrides,
) -> Config:
    """Build a :class:`Config` from a preset name and optional overrides: the one validator of a configuration.

    ``overrides`` are :class:`Preset` fields (``k``, ``gamma``, ``mu``, ...).
    ``dt_s``, ``t_max_s``, ``tol`` and ``tol_growth`` may be numbers or their
    text (a command's options, read here and nowhere else).
    ``dt_s="auto"`` picks the step with :func:`auto_dt` for impacts at
    ``v_impact_cm_s`` (cm/s; see :func:`impact_speed_cm_s`), or raises
    ConfigError when no step fits the budget.  ``tol``: the local error
    tolerance of the error-controlled integrators; ``tol_growth``: the rate,
    1/s, at which it loosens over a throw (see :class:`Numerics`).  When
    neither is given, an error-controlled integrator takes the preset's
    ``default_tol`` and ``default_tol_growth`` (``physical``: 2e-8 loosening
    at 10 /s), or ``Numerics``' defaults (a uniform 1e-7) when it has none.
    Either given to a fixed-step integrator has no effect: a UserWarning, or
    with ``strict`` a ConfigError.  Bad values raise :class:`ConfigError`
    naming the field.
    """
    if isinstance(preset, str):
        p = get_preset(preset)
    elif isinstance(preset, Preset):
        p = preset
    else:
        raise TypeError(f"preset must be a preset name or a dicetrace.params.Preset, not {type(preset).__name__}")
    if overrides:
        names = {f.name for f in fields(Preset)} - {"name"}
        unknown = sorted(set(overrides) - names)
        if unknown:
            raise TypeError(
                f"unknown preset parameter(s) {', '.join(unknown)} (choose from {', '.join(sorted(names))})"
            )
        p = p.with_(**overrides)
    kw = {"integrator": p.integrator if integrator is None else integrator}
    spec = _spec(kw["integrator"])
    if v_impact_cm_s is not None and (not _is_number(v_impact_cm_s) or not math.isfinite(v_impact_cm_s)
                                      or v_impact_cm_s < 0):
        raise ConfigError("v_impact_cm_s", f"v_impact_cm_s must be a finite number >= 0, got {_show(v_impact_cm_s)}")
    given = {"tol": tol, "tol_growth": tol_growth}
    auto = isinstance(dt_s, str) and dt_s.strip().lower() == "auto"
    for name, what, value in (("dt_s", "time step dt must be a number > 0 or 'auto'", None if auto else dt_s),
                              ("t_max_s", "time cap t_max must be a number > 0", t_max_s),
                              ("tol", f"tolerance tol must be a number in [{TOL_MIN:g}, 1)", tol),
                              ("tol_growth", "tolerance growth tol_growth must be a number (1/s)", tol_growth)):
        if value is not None:
            kw[name] = _read_number(name, what, value)
    if auto and _valid_positive(kw.get("t_max_s", Numerics.t_max_s)):  # else Numerics refuses the time cap below
        try:
            kw["dt_s"] = auto_dt(p, kw["integrator"], v_impact_cm_s=v_impact_cm_s,
                                 t_max_s=kw.get("t_max_s", Numerics.t_max_s), substeps=Numerics.substeps)
        except ValueError as e:
            raise ConfigError("dt_s", str(e)) from None
    if tol is None and tol_growth is None and spec.adaptive and p.default_tol is not None:
        kw["tol"], kw["tol_growth"] = p.default_tol, p.default_tol_growth  # the preset's schedule
    numerics = Numerics(**kw)
    for name, value in given.items():
        if value is not None and not spec.adaptive:
            msg = (f"{name} {_show(kw[name])} ({', '.join(n for n, sp in INTEGRATORS.items() if sp.adaptive)} only) "
                   f"has no effect on {kw['integrator']}, whose steps are fixed")
            if strict:
                raise ConfigError(name, msg)
            warnings.warn(msg, UserWarning, stacklevel=2)
    return Config(preset=p, numerics=numerics)


def resolve_config(config: "Config | str | None" = None, /, **options) -> Config:
    """The configuration of an API call: ``config`` itself, or :func:`make_config` of the options.

    Every entry point (``simulate``, ``simulate_batch``, ``scan``, the
    studies, the analysis callables) takes ``config=`` or the keyword options of :func:`make_config`
    (``preset``, ``integrator``, ``dt_s``, ``t_max_s``, ``tol``, ``tol_growth``,
    ``v_impact_cm_s`` and :class:`Preset` field overrides), never both: a
    given Config already fixes them.  ``config`` may also be a preset name.
    Options whose value is None count as not given.
    """
    options = {k: v for k, v in options.items() if v is not None}
    if config is None or isinstance(config, (str, Preset)):
        if config is not None:
            if "preset" in options:
                raise ConfigError("preset", "give the preset once: config='NAME' or preset='NAME'")
            options["preset"] = config
        return make_config(**options)
    if not isinstance(config, Config):
        raise TypeError(f"config must be a dicetrace.params.Config or a preset name, not {type(config).__name__}")
    if options:
        raise ConfigError(tuple(sorted(options)),
                          f"pass either config or {', '.join(sorted(options))}, not both (the config already fixes them)")
    return config
