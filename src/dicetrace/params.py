"""Validated, frozen configuration: the model preset and the numerics.

Bottom layer of dicetrace (imports nothing of the package).  Units are the
2019 program's: centimetres, seconds and "node mass" (each of the die's eight
corner nodes has mass 1, the die 8).  Force is node-mass·cm/s².

``Preset`` is the physical model, ``Numerics`` how it is integrated; both
convert themselves into :class:`KernelParams`, the plain ``NamedTuple`` of
floats that the numba kernels take.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import NamedTuple

#: Integrator names → kernel ids.  The order is part of the kernel ABI.
INTEGRATORS: dict[str, int] = {
    "semi-implicit-euler": 0,  # the 2019 program's scheme (default for `seed`)
    "forward-euler": 1,  # what the writeup claims it used
    "verlet": 2,  # velocity Verlet
    "rk4": 3,  # classical Runge-Kutta on the Lie group (commutator-free)
    "contact-substep": 4,  # semi-implicit Euler, sub-stepped while in contact
}

#: Classical order of accuracy of each integrator on smooth segments.
INTEGRATOR_ORDER: dict[str, int] = {
    "semi-implicit-euler": 1,
    "forward-euler": 1,
    "verlet": 2,
    "rk4": 4,
    "contact-substep": 1,
}

FRICTION_SPECTRAL = 0  # the program: −μ·P_k·u_xy,k / σ(all nodes' u_xy)
FRICTION_PER_NODE = 1  # physical: −μ·max(P_k,0)·u_xy,k / sqrt(|u_xy,k|² + v_reg²)

ENERGY_POINT_MASS = 0  # the program's stop-test energy (point-mass kinetic energy)
ENERGY_RIGID = 1  # kinetic energy with the inertia the dynamics use


class KernelParams(NamedTuple):
    """Flat float parameters for the numba kernels (field order is the ABI)."""

    k: float  # ground stiffness per node mass, 1/s²
    gamma: float  # damping coefficient, s/cm
    mu: float  # friction coefficient
    g: float  # gravity along z, cm/s² (negative)
    half: float  # half side of the cube, cm
    inertia: float  # isotropic moment of inertia, node-mass·cm²
    z0: float  # initial height of the centre of mass, cm
    dt: float  # time step, s
    max_steps: float  # time cap as a number of steps
    e_stop: float  # stop-test energy threshold
    e_offset: float  # energy offset subtracted in the stop-test energy
    friction_mode: float  # FRICTION_SPECTRAL or FRICTION_PER_NODE
    clamp_normal: float  # 1: normal force clamped at zero, 0: signed (program)
    energy_mode: float  # ENERGY_POINT_MASS or ENERGY_RIGID
    v_reg: float  # friction regularisation speed, cm/s (per-node mode)
    blowup_rel: float  # blow-up if E_dyn - E_rest > (1+rel)·(E0 - E_rest) + abs
    blowup_abs: float
    substeps: float  # sub-steps per step while in contact (contact-substep)


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
        Friction regularisation speed for ``"per-node"`` friction, cm/s.
    l_convention
        ``"program"``: an IC's L is the program's (−physical) angular momentum;
        ``"physical"``: it is the physical one.
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
    v_reg_cm_s: float = 1e-3
    l_convention: str = "program"

    def __post_init__(self) -> None:
        for name in ("k", "gamma", "mu", "g", "half_side_cm", "z0_cm", "v_reg_cm_s"):
            v = getattr(self, name)
            if not isinstance(v, (int, float)) or not math.isfinite(v):
                raise ValueError(f"preset {self.name!r}: {name} must be a finite number, got {v!r}")
        if self.k <= 0:
            raise ValueError(f"preset {self.name!r}: stiffness k must be > 0, got {self.k}")
        if self.gamma < 0 or self.mu < 0:
            raise ValueError(f"preset {self.name!r}: gamma and mu must be >= 0")
        if self.half_side_cm <= 0:
            raise ValueError(f"preset {self.name!r}: half_side_cm must be > 0")
        if self.v_reg_cm_s <= 0:
            raise ValueError(f"preset {self.name!r}: v_reg_cm_s must be > 0")
        if self.friction not in ("spectral", "per-node"):
            raise ValueError(f"preset {self.name!r}: friction must be 'spectral' or 'per-node', got {self.friction!r}")
        if self.energy not in ("point-mass", "rigid"):
            raise ValueError(f"preset {self.name!r}: energy must be 'point-mass' or 'rigid', got {self.energy!r}")
        if self.l_convention not in ("program", "physical"):
            raise ValueError(f"preset {self.name!r}: l_convention must be 'program' or 'physical'")

    @property
    def node_mass(self) -> float:
        return 1.0

    @property
    def inertia(self) -> float:
        """Isotropic moment of inertia (1/6)·M·s² with M = 8, s = side, node-mass·cm²."""
        side = 2.0 * self.half_side_cm
        return 8.0 * side * side / 6.0

    @property
    def e_rest(self) -> float:
        """Gravitational energy of the die lying on a face, Σ m·|g|·z = 8·|g|·half."""
        return 8.0 * (-self.g) * self.half_side_cm

    @property
    def e_stop(self) -> float:
        """Stop-test threshold: 80 % of the energy to stand the die on an edge.

        The program writes it as 0.8·(8·|g|·(√2 − 1)) for a unit half side.
        """
        return 0.8 * self.e_rest * (math.sqrt(2.0) - 1.0)

    def with_(self, **changes) -> "Preset":
        return replace(self, **changes)


PRESETS: dict[str, Preset] = {
    "seed": Preset(name="seed"),
    "physical": Preset(
        name="physical",
        friction="per-node",
        clamp_normal=True,
        energy="rigid",
        l_convention="physical",
    ),
}


def get_preset(name: str) -> Preset:
    try:
        return PRESETS[name]
    except KeyError:
        raise ValueError(f"unknown preset {name!r} (choose from {', '.join(PRESETS)})") from None


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
        Sub-steps per step while a node is in contact (``contact-substep`` only).
    """

    integrator: str = "semi-implicit-euler"
    dt_s: float = 0.001
    t_max_s: float = 60.0
    substeps: int = 8

    def __post_init__(self) -> None:
        if self.integrator not in INTEGRATORS:
            raise ValueError(
                f"unknown integrator {self.integrator!r} (choose from {', '.join(INTEGRATORS)})"
            )
        if not isinstance(self.dt_s, (int, float)) or not math.isfinite(self.dt_s) or self.dt_s <= 0:
            raise ValueError(f"time step dt must be a finite number > 0, got {self.dt_s!r}")
        if not isinstance(self.t_max_s, (int, float)) or not math.isfinite(self.t_max_s) or self.t_max_s <= 0:
            raise ValueError(f"time cap t_max must be a finite number > 0, got {self.t_max_s!r}")
        if self.t_max_s / self.dt_s > 2**40:
            raise ValueError("time cap / dt is too large")
        if int(self.substeps) != self.substeps or self.substeps < 1:
            raise ValueError(f"substeps must be an integer >= 1, got {self.substeps!r}")

    @property
    def max_steps(self) -> int:
        return int(math.ceil(self.t_max_s / self.dt_s - 1e-9))

    @property
    def integrator_id(self) -> int:
        return INTEGRATORS[self.integrator]

    @property
    def order(self) -> int:
        return INTEGRATOR_ORDER[self.integrator]


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

    def kernel_params(self) -> KernelParams:
        p, n = self.preset, self.numerics
        return KernelParams(
            k=float(p.k),
            gamma=float(p.gamma),
            mu=float(p.mu),
            g=float(p.g),
            half=float(p.half_side_cm),
            inertia=float(p.inertia),
            z0=float(p.z0_cm),
            dt=float(n.dt_s),
            max_steps=float(n.max_steps),
            e_stop=float(p.e_stop),
            e_offset=float(p.e_rest),
            friction_mode=float(FRICTION_SPECTRAL if p.friction == "spectral" else FRICTION_PER_NODE),
            clamp_normal=1.0 if p.clamp_normal else 0.0,
            energy_mode=float(ENERGY_POINT_MASS if p.energy == "point-mass" else ENERGY_RIGID),
            v_reg=float(p.v_reg_cm_s),
            blowup_rel=BLOWUP_REL,
            blowup_abs=BLOWUP_ABS_FRACTION * p.e_rest,
            substeps=float(n.substeps),
        )

    def as_dict(self) -> dict:
        """Plain dict of every parameter (stored in file metadata)."""
        from dataclasses import asdict

        return {"preset": asdict(self.preset), "numerics": asdict(self.numerics)}


def make_config(
    preset: str | Preset = "seed",
    *,
    integrator: str | None = None,
    dt_s: float | None = None,
    t_max_s: float | None = None,
    **overrides,
) -> Config:
    """Build a :class:`Config` from a preset name and optional overrides.

    ``overrides`` are :class:`Preset` fields (``k``, ``gamma``, ``mu``, ...).
    """
    p = get_preset(preset) if isinstance(preset, str) else preset
    if overrides:
        p = p.with_(**overrides)
    kw = {}
    if integrator is not None:
        kw["integrator"] = integrator
    if dt_s is not None:
        kw["dt_s"] = dt_s
    if t_max_s is not None:
        kw["t_max_s"] = t_max_s
    return Config(preset=p, numerics=Numerics(**kw))
