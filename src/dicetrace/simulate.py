"""The Python API of one throw (``simulate``) and of many (``simulate_batch``).

Converts at the boundary: ICs in, validated and put in the kernel's sign
convention; a :class:`Roll` out, with the status as a name, the contact-set
sequence in the program's text form, per-node contact events, and only the
trace channels that the :class:`Record` request asked for.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from dicetrace.core.contacts import contact_sets_from_heights
from dicetrace.core.loop import ENERGY_COLS, FORCE_COLS, STATE_COLS, run_batch, run_roll
from dicetrace.core.model import BUFFER_FULL, NODE_SIGNS, NON_FINITE
from dicetrace.ics import validate_ic, validate_ics
from dicetrace.params import Config, make_config

STATUS_NAMES = {0: "settled", 1: "time_cap", 2: "non_finite", 3: "blow_up"}
STATUS_ADVICE = {
    "settled": "the die came to rest; outcome is the face up (0: the top four nodes are no face)",
    "time_cap": "the throw did not settle before the time cap (raise t_max_s, or it balances on an edge)",
    "non_finite": "the state became NaN or infinite: the time step is too large for the stiffness",
    "blow_up": "the energy grew beyond its start: a numerical blow-up (reduce dt or use another integrator)",
}
ENERGY_NAMES = ("stop_test", "kinetic_translational", "kinetic_rotational", "gravitational", "elastic", "total")

_INITIAL_CAP = 256


class SimulationError(RuntimeError):
    """A run ended in a numerical failure (non-finite state or energy blow-up)."""


@dataclass(frozen=True)
class Record:
    """Which per-step channels a simulation computes and keeps.

    Parameters
    ----------
    states
        Node positions, centre of mass (position, velocity), orientation
        quaternion and angular momentum, every step.
    energy
        Energies every step (stop-test, translational and rotational kinetic,
        gravitational, elastic, total), node-mass·cm²/s².
    forces
        Contact force on every node, every step.
    """

    states: bool = True
    energy: bool = True
    forces: bool = False

    def __post_init__(self) -> None:
        if not (self.states or self.energy or self.forces):
            raise ValueError("Record() asks for nothing: request states, energy or forces, or pass record=None")


@dataclass
class Trace:
    """Per-step channels of one throw (row n = after n steps; row 0 the IC).

    Positions in cm, velocities in cm/s, times in s.  ``L`` is in the
    preset's convention.  Absent channels are ``None``.
    """

    step: np.ndarray
    t_s: np.ndarray
    cm_pos: np.ndarray | None = None  # (n+1, 3)
    cm_vel: np.ndarray | None = None  # (n+1, 3)
    L: np.ndarray | None = None  # (n+1, 3)
    node_offsets: np.ndarray | None = None  # (n+1, 8, 3) relative to the centre of mass
    forces: np.ndarray | None = None  # (n+1, 8, 3)
    energy: dict[str, np.ndarray] | None = None

    @property
    def node_pos(self) -> np.ndarray | None:
        """Absolute node positions (n+1, 8, 3), cm."""
        if self.node_offsets is None:
            return None
        return self.cm_pos[:, None, :] + self.node_offsets

    @property
    def rotation(self) -> np.ndarray | None:
        """World-from-body rotation matrices (n+1, 3, 3) read off the node offsets."""
        if self.node_offsets is None:
            return None
        half = np.abs(self.node_offsets[0]).max()
        # column j: Σ_k sign_kj · x_k / (8·half) is body axis j in the world frame
        return np.einsum("kj,nki->nij", NODE_SIGNS, self.node_offsets) / (8.0 * half)

    @property
    def quat_xyzw(self) -> np.ndarray | None:
        """Orientation quaternions (n+1, 4) in (x, y, z, w) order, world from body."""
        rot = self.rotation
        if rot is None:
            return None
        from scipy.spatial.transform import Rotation

        return Rotation.from_matrix(rot).as_quat()


@dataclass
class Roll:
    """The result of one throw.

    Attributes
    ----------
    ic : (6,) U (cm/s) and L in the preset's convention.
    outcome : face up 1..6; 0 when the top four nodes are no face; -1 unless settled.
    status : "settled", "time_cap", "non_finite" or "blow_up".
    steps : steps integrated; ``t_settle_s = steps·dt``.
    contact_sets : uint8 bitmasks (bit k = node k+1 at or below the ground).
    contact_steps : step at which each set was first seen (0 for the initial empty set).
    """

    ic: np.ndarray
    outcome: int
    status: str
    steps: int
    t_settle_s: float
    dt_s: float
    contact_sets: np.ndarray
    contact_steps: np.ndarray
    config: Config
    trace: Trace | None = field(default=None, repr=False)

    @property
    def settled(self) -> bool:
        return self.status == "settled"

    @property
    def contact_sequence(self) -> str:
        """The program's text form, e.g. ``0-6-68-8-0-3``."""
        return sets_to_text(self.contact_sets)

    @property
    def n_contact_changes(self) -> int:
        return int(len(self.contact_sets) - 1)

    def contact_events(self):
        """Per-node events as a DataFrame: step, t_s, node (1..8), kind ("enter"/"leave")."""
        import pandas as pd

        steps, nodes, kinds = contact_events(self.contact_sets, self.contact_steps)
        return pd.DataFrame(
            {"step": steps, "t_s": steps * self.dt_s, "node": nodes, "kind": np.where(kinds, "enter", "leave")}
        )


def set_to_text(mask: int) -> str:
    """One contact set as text: node numbers ascending, ``0`` for the empty set."""
    mask = int(mask)
    return "".join(str(k + 1) for k in range(8) if mask >> k & 1) or "0"


def sets_to_text(sets) -> str:
    """The program's text form of a contact-set sequence (sets joined by ``-``)."""
    return "-".join(set_to_text(m) for m in sets)


def text_to_sets(text: str) -> np.ndarray:
    """Inverse of :func:`sets_to_text`."""
    out = []
    for part in text.split("-"):
        mask = 0
        if part != "0":
            for ch in part:
                node = int(ch)
                if not 1 <= node <= 8:
                    raise ValueError(f"bad node {ch!r} in contact sequence {text!r}")
                mask |= 1 << (node - 1)
        out.append(mask)
    return np.array(out, dtype=np.uint8)


def contact_events(sets, set_steps):
    """Per-node events between consecutive contact sets.

    Returns arrays (step, node 1..8, entered: bool), ordered by step then node.
    """
    steps, nodes, kinds = [], [], []
    prev = 0
    for mask, st in zip(np.asarray(sets, dtype=np.int64), np.asarray(set_steps, dtype=np.int64)):
        changed = prev ^ mask
        for k in range(8):
            if changed >> k & 1:
                steps.append(st)
                nodes.append(k + 1)
                kinds.append(bool(mask >> k & 1))
        prev = mask
    return np.array(steps, dtype=np.int64), np.array(nodes, dtype=np.int8), np.array(kinds, dtype=bool)


def contact_sequence_from_heights(z_steps) -> tuple[np.ndarray, np.ndarray]:
    """Contact sets and their steps from a height series (nstep+1, 8), cm."""
    z = np.ascontiguousarray(z_steps, dtype=np.float64)
    if z.ndim != 2 or z.shape[1] != 8:
        raise ValueError(f"height series must be (nstep+1, 8), got {z.shape}")
    sets = np.zeros(z.shape[0] + 1, dtype=np.uint8)
    steps = np.zeros(z.shape[0] + 1, dtype=np.int32)
    n = contact_sets_from_heights(z, sets, steps)
    return sets[:n].copy(), steps[:n].copy()


def _resolve_config(config, preset, integrator, dt_s, t_max_s, tol=None) -> Config:
    if config is not None:
        return config
    return make_config(preset, integrator=integrator, dt_s=dt_s, t_max_s=t_max_s, tol=tol)


def _to_kernel_ic(ic: np.ndarray, config: Config) -> np.ndarray:
    if config.preset.l_convention == "physical":
        ic = ic.copy()
        ic[..., 3:] = -ic[..., 3:]
    return ic


def initial_offsets(config: Config, orientation=None) -> np.ndarray:
    """Initial node offsets (8, 3), cm: ±half on each axis, turned by ``orientation``.

    ``orientation`` is a world-from-body rotation matrix (3, 3) or None for
    the program's start (face 3 down, face 4 up).
    """
    off = NODE_SIGNS * config.preset.half_side_cm
    if orientation is None:
        return np.ascontiguousarray(off)
    rot = np.asarray(orientation, dtype=np.float64)
    if rot.shape != (3, 3) or not np.all(np.isfinite(rot)):
        raise ValueError("orientation must be a finite 3×3 rotation matrix")
    if np.abs(rot @ rot.T - np.eye(3)).max() > 1e-9 or np.linalg.det(rot) < 0:
        raise ValueError("orientation is not a rotation matrix (RᵀR ≠ I or det < 0)")
    return np.ascontiguousarray(off @ rot.T)


def _check_integrator(config: Config) -> None:
    from dicetrace.core.integrators import IMPLEMENTED

    if config.numerics.integrator_id not in IMPLEMENTED:
        raise ValueError(f"integrator {config.numerics.integrator!r} is not available in this build")


def simulate(
    ic,
    *,
    config: Config | None = None,
    preset: str = "seed",
    integrator: str | None = None,
    dt_s: float | None = None,
    t_max_s: float | None = None,
    tol: float | None = None,
    record: Record | None = None,
    orientation=None,
) -> Roll:
    """Throw the die once.

    Parameters
    ----------
    ic
        (vx, vy, vz, Lx, Ly, Lz): velocity in cm/s and angular momentum in
        node-mass·cm²/s, L in the preset's convention (``seed``: the 2019
        program's, the negative of the physical L).
    config
        A full :class:`~dicetrace.params.Config`; otherwise built from
        ``preset``, ``integrator``, ``dt_s`` (s), ``t_max_s`` (s) and ``tol``
        (the local error tolerance of ``contact-adaptive``).
    record
        Per-step channels to compute (None: summary only, nothing per step).
    orientation
        Initial world-from-body rotation matrix (3, 3); None: the program's
        start (identity: face 3 down).

    Returns
    -------
    Roll
    """
    cfg = _resolve_config(config, preset, integrator, dt_s, t_max_s, tol)
    _check_integrator(cfg)
    ic = validate_ic(ic)
    kic = _to_kernel_ic(ic, cfg)
    kp = cfg.kernel_params()
    off0 = initial_offsets(cfg, orientation)
    integ = cfg.numerics.integrator_id
    empty = (np.zeros((0, STATE_COLS)), np.zeros((0, FORCE_COLS)), np.zeros((0, ENERGY_COLS)))
    cap = _INITIAL_CAP
    while True:
        sets = np.zeros(cap, dtype=np.uint8)
        set_steps = np.zeros(cap, dtype=np.int32)
        status, n, outcome, nsets = run_roll(kic, off0, kp, integ, sets, set_steps, *empty)
        if status != BUFFER_FULL:
            break
        cap *= 4
    trace = None
    if record is not None:
        rows = n + 1
        tr_state = np.zeros((rows if record.states else 0, STATE_COLS))
        tr_force = np.zeros((rows if record.forces else 0, FORCE_COLS))
        tr_energy = np.zeros((rows if record.energy else 0, ENERGY_COLS))
        run_roll(kic, off0, kp, integ, sets, set_steps, tr_state, tr_force, tr_energy)
        if status == NON_FINITE:  # the last step's state is not finite: keep the rows before it
            rows = n
            tr_state, tr_force, tr_energy = tr_state[:rows], tr_force[:rows], tr_energy[:rows]
        trace = _make_trace(rows - 1, cfg, tr_state, tr_force, tr_energy, record)
    dt = cfg.numerics.dt_s
    return Roll(
        ic=ic,
        outcome=int(outcome),
        status=STATUS_NAMES[int(status)],
        steps=int(n),
        t_settle_s=n * dt,
        dt_s=dt,
        contact_sets=sets[:nsets].copy(),
        contact_steps=set_steps[:nsets].copy(),
        config=cfg,
        trace=trace,
    )


def _make_trace(n, cfg, tr_state, tr_force, tr_energy, record) -> Trace:
    step = np.arange(n + 1, dtype=np.int64)
    tr = Trace(step=step, t_s=step * cfg.numerics.dt_s)
    if record.states:
        sign = -1.0 if cfg.preset.l_convention == "physical" else 1.0
        tr.cm_pos = tr_state[:, 0:3].copy()
        tr.cm_vel = tr_state[:, 3:6].copy()
        tr.L = sign * tr_state[:, 6:9]
        tr.node_offsets = tr_state[:, 9:33].reshape(n + 1, 8, 3).copy()
    if record.forces:
        tr.forces = tr_force.reshape(n + 1, 8, 3).copy()
    if record.energy:
        tr.energy = {name: tr_energy[:, j].copy() for j, name in enumerate(ENERGY_NAMES)}
    return tr


@dataclass
class BatchResult:
    """Summaries of many throws (arrays aligned with the input ICs)."""

    ics: np.ndarray
    outcome: np.ndarray  # int8
    status_code: np.ndarray  # int8
    steps: np.ndarray  # int64
    t_settle_s: np.ndarray  # float64
    set_offsets: np.ndarray  # int64 (m+1,): sets of IC i are sets[set_offsets[i]:set_offsets[i+1]]
    sets: np.ndarray  # uint8
    set_steps: np.ndarray  # int32
    config: Config

    def __len__(self) -> int:
        return len(self.outcome)

    @property
    def status(self) -> np.ndarray:
        return np.array([STATUS_NAMES[int(s)] for s in self.status_code], dtype=object)

    def contact_sets(self, i: int) -> np.ndarray:
        return self.sets[self.set_offsets[i] : self.set_offsets[i + 1]]

    def contact_sequences(self) -> list[str]:
        return [sets_to_text(self.contact_sets(i)) for i in range(len(self))]


def simulate_batch(
    ics,
    *,
    config: Config | None = None,
    preset: str = "seed",
    integrator: str | None = None,
    dt_s: float | None = None,
    t_max_s: float | None = None,
    tol: float | None = None,
    cap: int = 128,
) -> BatchResult:
    """Throw the die from every row of ``ics`` (m, 6), in parallel (numba threads).

    Summary path only; bit-identical to calling :func:`simulate` row by row.
    ``cap`` is the initial per-IC contact-set buffer (throws that need more
    are re-run with a larger one).
    """
    cfg = _resolve_config(config, preset, integrator, dt_s, t_max_s, tol)
    _check_integrator(cfg)
    ics = validate_ics(ics)
    kics = _to_kernel_ic(ics, cfg)
    kp = cfg.kernel_params()
    integ = cfg.numerics.integrator_id
    m = len(ics)
    status = np.zeros(m, dtype=np.int8)
    steps = np.zeros(m, dtype=np.int64)
    outcome = np.zeros(m, dtype=np.int8)
    nsets = np.zeros(m, dtype=np.int64)
    sets = np.zeros(m * cap, dtype=np.uint8)
    set_steps = np.zeros(m * cap, dtype=np.int32)
    if m:
        run_batch(kics, initial_offsets(cfg), kp, integ, cap, status, steps, outcome, nsets, sets, set_steps)
    sets2 = sets.reshape(m, cap)
    steps2 = set_steps.reshape(m, cap)
    seq_sets, seq_steps = [], []
    for i in range(m):
        if status[i] == BUFFER_FULL:
            r = simulate(ics[i], config=cfg)
            status[i] = {v: k for k, v in STATUS_NAMES.items()}[r.status]
            steps[i] = r.steps
            outcome[i] = r.outcome
            nsets[i] = len(r.contact_sets)
            seq_sets.append(r.contact_sets)
            seq_steps.append(r.contact_steps)
        else:
            seq_sets.append(sets2[i, : nsets[i]])
            seq_steps.append(steps2[i, : nsets[i]])
    offsets = np.zeros(m + 1, dtype=np.int64)
    np.cumsum(nsets, out=offsets[1:])
    return BatchResult(
        ics=ics,
        outcome=outcome,
        status_code=status,
        steps=steps,
        t_settle_s=steps * cfg.numerics.dt_s,
        set_offsets=offsets,
        sets=np.concatenate(seq_sets) if m else np.zeros(0, np.uint8),
        set_steps=np.concatenate(seq_steps) if m else np.zeros(0, np.int32),
        config=cfg,
    )
