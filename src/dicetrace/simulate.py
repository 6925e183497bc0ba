"""The Python API of one throw (``simulate``) and of many (``simulate_batch``).

Converts at the boundary: ICs in, validated and put in the kernel's sign
convention; a :class:`Roll` out, with the status as a name, the contact-set
sequence in the program's text form, per-node contact events, and only what
the :class:`Record` request asked for (trace channels, exact contact events).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from dicetrace.batch_chunks import (
    CAP_GROWTH,
    DEFAULT_CAP,
    MAX_CAP,
    batch_chunk,
    check_batch_memory,
    chunk_results,
    gpu_batch_chunk,
    join_parts,
    run_chunk,
)
from dicetrace.compile_clock import say_first_compile
from dicetrace.core.contacts import contact_sets_from_heights
from dicetrace.core.kernels import has_events, new_roll_state, roll_out_for, run_roll, run_throw
from dicetrace.core.loop import ENERGY_COLS, FORCE_COLS, STATE_COLS
from dicetrace.core.state import SUBSTEP_CAUSES
from dicetrace.devices import CPU as CPU_DEVICE
from dicetrace.devices import Device, check_device, resolve_device
from dicetrace.integrators import INTEGRATORS
from dicetrace.ic_arrays import (SliceICs, quaternions_xyzw, validate_heights, validate_ic, validate_ics,
                                 validate_orientations)
from dicetrace.memory import available_memory
from dicetrace.body import rotations
from dicetrace.params import Config, resolve_config
from dicetrace.saving import NOT_GIVEN, Record, record_with_events, summary_record, wants_events
from dicetrace.status import Status

say_first_compile()  # a first call from Python compiles for seconds to minutes: say so once, on standard error

ENERGY_NAMES = ("stop_test", "kinetic_translational", "kinetic_rotational", "gravitational", "elastic", "total")


class SimulationError(RuntimeError):
    """A run ended in a numerical failure (non-finite state or energy blow-up)."""


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
        return rotations(self.node_offsets)

    @property
    def written(self) -> np.ndarray:
        """Boolean mask of the rows that hold a state.

        A run that ends in a numerical failure may leave its last row
        unwritten (all zeros): no real state has all eight node offsets zero,
        so such rows are masked out.
        """
        return ~(self.node_offsets == 0.0).all(axis=(1, 2))

    @property
    def quat_xyzw(self) -> np.ndarray | None:
        """Unit orientation quaternions (n+1, 4) in (x, y, z, w) order, world from body.

        Rows whose state is not finite or not written (a numerical failure) are NaN.
        """
        rot = self.rotation
        if rot is None:
            return None
        q = np.full((len(rot), 4), np.nan)
        ok = np.isfinite(rot).all(axis=(1, 2)) & self.written
        if ok.any():
            from scipy.spatial.transform import Rotation  # slow to import (scipy.spatial): only when asked for

            q[ok] = Rotation.from_matrix(rot[ok]).as_quat()
        return q


@dataclass
class Roll:
    """The result of one throw.

    Attributes
    ----------
    ic : (6,) U (cm/s) and L in the preset's convention.
    outcome : face up 1..6; 0 when the top four nodes are no face; -1 unless settled.
    status : a :class:`~dicetrace.Status` (compares equal to its label, e.g. ``"settled"``).
    steps : steps integrated; ``t_settle_s = steps·dt``.
    contact_sets : uint8 bitmasks (bit k = node k+1 at or below the ground).
    contact_steps : step at which each set was first seen (0 for the initial empty set); with
        exact contact events (``Record(events=True)``), the step it began in.
    contact_times : with ``simulate(..., record=Record(..., events=True))``, the time (s) each set
        began, exactly (docs/model.md §8.1: the set inside every sub-step of a contact scheme); None otherwise.
    substeps : the contact schemes' sub-steps by what ended them: accepted
        sub-steps whose length the error control chose (``error``), at the
        longest sub-step dt / substeps (``cap``), shortened by the friction
        law's stability bound (``friction``), to the end of a step (``end``)
        or to a node entering or leaving the ground (``cut``); attempts
        rejected by the error control (``rejected``) and attempts computed
        again, shorter, at a cut (``redone``).  All zero for the other schemes.
    """

    ic: np.ndarray
    outcome: int
    status: Status
    steps: int
    t_settle_s: float
    dt_s: float
    contact_sets: np.ndarray
    contact_steps: np.ndarray
    config: Config
    trace: Trace | None = field(default=None, repr=False)
    substeps: dict = field(default_factory=dict, repr=False)
    contact_times: np.ndarray | None = field(default=None, repr=False)

    @property
    def settled(self) -> bool:
        return self.status is Status.SETTLED

    @property
    def contact_sequence(self) -> str:
        """The program's text form, e.g. ``0-6-68-8-0-3``."""
        return sets_to_text(self.contact_sets)

    @property
    def n_contact_changes(self) -> int:
        return int(len(self.contact_sets) - 1)

    def contact_events(self):
        """Per-node events as a DataFrame: step, t_s, node (1..8), kind ("enter"/"leave").

        ``t_s`` is step·dt, or the exact time of the event where the throw
        recorded them (``Record(events=True)``).
        """
        import pandas as pd  # pandas is slow to import: only when used

        from dicetrace.tables import node_events  # the contacts table's events (lazy: pyarrow, through dicetrace.tables)

        _, steps, t, nodes, entered = node_events(self)
        return pd.DataFrame({"step": steps, "t_s": t, "node": nodes, "kind": np.where(entered, "enter", "leave")})


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


def contact_sequence_from_heights(z_steps) -> tuple[np.ndarray, np.ndarray]:
    """Contact sets and their steps from a height series (nstep+1, 8), cm."""
    z = np.ascontiguousarray(z_steps, dtype=np.float64)
    if z.ndim != 2 or z.shape[1] != 8:
        raise ValueError(f"height series must be (nstep+1, 8), got {z.shape}")
    sets = np.zeros(z.shape[0] + 1, dtype=np.uint8)
    steps = np.zeros(z.shape[0] + 1, dtype=np.int32)
    n = contact_sets_from_heights(z, sets, steps)
    return sets[:n].copy(), steps[:n].copy()


def check_events(cfg: Config, events, what: str = "events=True") -> bool:
    """``events`` as a bool, refused (ValueError, its words after ``what``) where the integrator has no exact
    contact events."""
    if not isinstance(events, (bool, np.bool_)):
        raise ValueError(f"events must be True or False, not {events!r}")
    if events and not has_events(INTEGRATORS[cfg.numerics.integrator].kernel_id):
        raise ValueError(
            f"{what}: integrator {cfg.numerics.integrator!r} has no exact contact events; the contact integrators "
            "(contact-substep, contact-adaptive, contact-tsit5, contact-dop853) have them (a fixed-step scheme sees "
            "contacts only at step ends, which the contact sequence records)"
        )
    return bool(events)


def simulate(ic, *, config: Config | str | None = None, record: Record | None = None, orientation=None,
             events=NOT_GIVEN, **options) -> Roll:
    """Throw the die once.

    Parameters
    ----------
    ic
        (vx, vy, vz, Lx, Ly, Lz): velocity in cm/s and angular momentum in
        node-mass·cm²/s, L in the preset's convention (``seed``: the 2019
        program's, the negative of the physical L).
    config, **options
        A full :class:`~dicetrace.params.Config` (or a preset name), or the
        keyword options of :func:`~dicetrace.params.make_config`: ``preset``
        (default ``"seed"``), ``integrator``, ``dt_s`` (s, or ``"auto"``),
        ``t_max_s`` (s), ``tol`` (the local error tolerance of
        ``contact-adaptive``) and Preset field overrides (``k``, ``gamma``,
        ...); never both (see :func:`~dicetrace.params.resolve_config`).
    record
        What to keep besides the summary, a :class:`~dicetrace.Record`: the
        per-step trace channels (``Roll.trace``) and the exact contact events
        (``events=True``; contact integrators only; docs/model.md §8.1): the
        contact sets are then the sets inside the scheme's sub-steps, located
        where nodes enter or leave the ground, with their times
        (``Roll.contact_times``), instead of the sets at output-step ends.
        The events are read off beside the integration: the throw is the
        same without them, bit for bit (status, steps, outcome); they cost
        CPU time (docs/model.md §8.1).  None: the summary only, nothing per step.
    orientation
        Initial world-from-body rotation matrix (3, 3); None: the program's
        start (identity: face 3 down).
    events
        Deprecated: ``events=True`` is ``record=Record.events_only()`` (with a
        ``record``: the same with ``events=True``); it warns, and goes in the
        next release.

    Returns
    -------
    Roll
    """
    cfg = resolve_config(config, **options)
    record = record_with_events(record, events, "simulate")
    ic = validate_ic(ic)
    _check_orientation(orientation)
    events = check_events(cfg, wants_events(record), "record=Record(events=True)")
    kin = cfg.kernel_inputs(ic, orientation=orientation)
    cap = DEFAULT_CAP
    state = new_roll_state(kin.integrator_id)
    while True:  # the summary (with the exact events where asked): no trace rows
        out = roll_out_for(cap, record)
        summary = run_throw(*kin, out, record, state=state)
        if summary[0] != Status.BUFFER_FULL:
            break
        cap *= CAP_GROWTH
    status, n, outcome, nsets = summary
    sets, set_steps, times = out.sets, out.set_steps, out.ev_times
    substeps = dict(zip(SUBSTEP_CAUSES, (int(c) for c in state[0][0]["substeps"])))
    trace = None
    if record is not None and record.traces:
        # The summary told how many rows the trace needs; the trace run is the
        # same arithmetic (the trace path writes, never steers), so it must end
        # the same way: anything else is a kernel defect, never silently kept.
        rows = n + 1
        check_trace_memory(rows, record, cfg)
        traced_out = roll_out_for(cap, replace(record, events=False), rows)  # the tracing loop: no events
        tr_state, tr_force, tr_energy = traced_out.tr_state, traced_out.tr_force, traced_out.tr_energy
        traced = run_roll(*kin, traced_out)
        same = 3 if events else 4  # (status, steps, outcome): the sets are the events'
        if tuple(int(v) for v in traced)[:same] != tuple(int(v) for v in summary)[:same]:
            raise RuntimeError(
                f"the trace run ended as (status, steps, outcome, sets) = {tuple(map(int, traced))}, "
                f"the summary run as {tuple(map(int, summary))}: kernel paths disagree (a bug; please report it)"
            )
        if status == Status.NON_FINITE:  # the last step's state is not finite: keep the rows before it
            rows = n
            tr_state, tr_force, tr_energy = tr_state[:rows], tr_force[:rows], tr_energy[:rows]
        trace = _make_trace(rows - 1, cfg, tr_state, tr_force, tr_energy, record)
    dt = cfg.numerics.dt_s
    return Roll(
        ic=ic,
        outcome=int(outcome),
        status=Status(int(status)),
        steps=int(n),
        t_settle_s=n * dt,
        dt_s=dt,
        contact_sets=sets[:nsets].copy(),
        contact_steps=set_steps[:nsets].copy(),
        config=cfg,
        trace=trace,
        substeps=substeps,
        contact_times=times[:nsets].copy() if events else None,
    )


def _integer(v, name: str, lo: int, hi: int | None = None, *, none_ok: bool = False) -> int | None:
    """``v`` as a Python int in [lo, hi] (None passes when ``none_ok``), else ValueError naming ``name``.

    Python and numpy integers of every width are accepted and converted, so
    that arithmetic on them (a buffer growing ``CAP_GROWTH``-fold) cannot wrap
    around; bools, floats (NaN, 2.0), strings and arrays are refused.
    """
    if v is None and none_ok:
        return None
    if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, np.integer)) or int(v) < lo:
        shown = v.item() if isinstance(v, np.generic) else v
        raise ValueError(f"{name} must be an integer >= {lo}{' or None' if none_ok else ''}, got {shown!r}")
    n = int(v)
    if hi is not None and n > hi:
        raise ValueError(f"{name} must be at most {hi:,}, got {n:,}")
    return n


def _check_orientation(orientation) -> None:
    if orientation is None:
        return
    try:
        a = np.asarray(orientation)
    except (TypeError, ValueError):  # ragged rows
        a = np.asarray(None)
    if a.dtype.kind not in "iuf":  # complex, bool, text, objects: refused, not cast
        what = type(orientation).__name__ if a.dtype.kind in "OUS" else f"dtype {a.dtype}"
        raise ValueError(f"orientation must be a 3×3 rotation matrix of real numbers, got {what}")
    rot = a.astype(np.float64)
    if rot.shape != (3, 3):
        raise ValueError(f"orientation must be a 3×3 rotation matrix, got shape {rot.shape}")


def trace_bytes(rows: int, record: Record) -> int:
    """Bytes of the per-step trace arrays of ``rows`` rows (states, forces, energy as requested)."""
    cols = STATE_COLS * bool(record.states) + FORCE_COLS * bool(record.forces) + ENERGY_COLS * bool(record.energy)
    return int(rows) * cols * 8


def check_trace_memory(rows: int, record: Record, cfg: Config, *, factor: float = 1.0, what: str = "record") -> None:
    """Refuse (ValueError naming ``what``) a trace whose arrays, times ``factor``, exceed the available memory."""
    need = trace_bytes(rows, record) * factor
    avail = available_memory()
    if avail is not None and need > avail:
        raise ValueError(
            f"{what}: the trace of {rows - 1:,} steps (dt {cfg.numerics.dt_s:g} s, time cap {cfg.numerics.t_max_s:g} s) "
            f"needs about {need / 2**30:.3g} GiB, more than the {avail / 2**30:.3g} GiB of memory available: "
            "use a larger dt, a shorter time cap, or record fewer channels"
        )


def _make_trace(n, cfg, tr_state, tr_force, tr_energy, record) -> Trace:
    step = np.arange(n + 1, dtype=np.int64)
    tr = Trace(step=step, t_s=step * cfg.numerics.dt_s)
    if record.states:
        tr.cm_pos = tr_state[:, 0:3].copy()
        tr.cm_vel = tr_state[:, 3:6].copy()
        tr.L = np.array(cfg.to_preset_convention(tr_state[:, 3:9], "program")[:, 3:])
        tr.node_offsets = tr_state[:, 9:33].reshape(n + 1, 8, 3).copy()
    if record.forces:
        tr.forces = tr_force.reshape(n + 1, 8, 3).copy()
    if record.energy:
        tr.energy = {name: tr_energy[:, j].copy() for j, name in enumerate(ENERGY_NAMES)}
    return tr


@dataclass
class BatchResult:
    """Summaries of many throws (arrays aligned with the input ICs).

    ``ics`` are in the preset's L convention.  The contact-set sequence of IC
    i is ``sets[set_offsets[i]:set_offsets[i+1]]`` (first seen at the steps
    ``set_steps[...]`` of the same range).  ``coords`` (m, 3): the ICs' slice
    coordinates x, y, z (NaN where none) when the ICs came with them (a
    :class:`~dicetrace.ics.SliceICs`, e.g. from :func:`~dicetrace.ics.seed_slice`),
    else None; the tables fill their ``x, y, z`` columns from them.
    ``device``: where the throws ran (``dicetrace.devices.device_label``).
    ``set_times``: with ``simulate_batch(..., record=Record.events_only())``, the exact time
    (s) each set began (the sets are then the exact contact events,
    docs/model.md §8.1, and ``set_steps`` the steps they began in); None
    otherwise.
    """

    ics: np.ndarray  # (m, 6) float64
    outcome: np.ndarray  # int8
    status_code: np.ndarray  # int8 codes of dicetrace.Status
    steps: np.ndarray  # int64
    t_settle_s: np.ndarray  # float64
    set_offsets: np.ndarray  # int64 (m+1,)
    sets: np.ndarray  # uint8
    set_steps: np.ndarray  # int32
    config: Config
    coords: np.ndarray | None = None  # (m, 3) float64 slice coordinates, NaN where none
    device: str = "cpu"  # where the throws ran: "cpu" or "cuda: <GPU name>" (also in the tables' metadata)
    set_times: np.ndarray | None = None  # float64 like ``sets``: each set's exact start time (s), with events
    orientations: np.ndarray | None = None  # (m, 4) x, y, z, w: each throw's starting orientation, when given
    heights_cm: np.ndarray | None = None  # (m,): each throw's start height of the centre of mass, when given

    def __len__(self) -> int:
        return len(self.outcome)

    @property
    def status(self) -> np.ndarray:
        """Status labels (object array of str)."""
        return Status.labels_of(self.status_code)

    def contact_sets(self, i: int) -> np.ndarray:
        return self.sets[self.set_offsets[i] : self.set_offsets[i + 1]]

    def contact_sequences(self) -> list[str]:
        return [sets_to_text(self.contact_sets(i)) for i in range(len(self))]

    def to_arrow(self, *, ic_ids=None, coords=None, metadata: dict | None = None):
        """The ``rolls`` table of these throws (the Parquet sink's schema), as a pyarrow Table.

        ``coords``: slice coordinates for the ``x, y, z`` columns (see
        :func:`~dicetrace.tables.rolls_table`); default: the batch's own
        (``self.coords``, from ICs that carried them), else null.  With exact
        contact events (``set_times``) it has a column ``contact_times_s``.
        """
        from dicetrace.tables import rolls_table  # lazy: pyarrow (through dicetrace.tables) only for this export

        return rolls_table(self, ic_ids=ic_ids, coords=coords, metadata=metadata)

    def to_pandas(self, **kwargs):
        """The ``rolls`` table as a pandas DataFrame (see :meth:`to_arrow`)."""
        return self.to_arrow(**kwargs).to_pandas()


def simulate_batch(
    ics,
    *,
    config: Config | str | None = None,
    l_convention: str | None = None,
    threads: int | None = None,
    cap: int = DEFAULT_CAP,
    chunk: int | None = None,
    device: str | Device | None = None,
    record: Record | None = None,
    orientations=None,
    heights_cm=None,
    events=NOT_GIVEN,
    **options,
) -> BatchResult:
    """Throw the die from every row of ``ics`` (m, 6), in parallel (numba threads, or a GPU).

    The one door onto the batch kernel (scans and studies call it).  Summary
    path only; bit-identical to calling :func:`simulate` row by row, whatever
    the number of threads.

    Parameters
    ----------
    ics
        (m, 6) ICs, L in ``l_convention`` (default: the preset's).  ICs that
        carry slice coordinates (a :class:`~dicetrace.ics.SliceICs`, as
        :func:`~dicetrace.ics.seed_slice` returns) pass them on to the
        result (``BatchResult.coords``, the table's ``x, y, z``).
    config, **options
        As in :func:`simulate`.
    threads
        numba threads for this call (None: numba's current setting; more
        than numba was started with, ``NUMBA_NUM_THREADS``, run as that many).
    cap
        Initial per-IC contact-set buffer, an integer in [1, ``MAX_CAP``];
        throws that need more are re-run (all together, in parallel) with
        ``CAP_GROWTH`` times more until they fit.
    chunk
        ICs run per call of the kernel (None: :func:`~dicetrace.batch_chunks.batch_chunk`, about
        64 MiB of buffers).  The ICs run chunk by chunk and only each chunk's
        contact sets are kept, compacted, so the memory a batch takes is its
        result (about 40 bytes per IC and 5 per contact set, 48 more per IC
        when the ICs are returned in another L convention) plus one chunk; the
        result is the same, bit for bit, whatever the chunk.  A batch whose
        result and chunk cannot fit in the memory available is refused before
        anything runs (a ValueError naming the sizes; see :func:`~dicetrace.batch_chunks.check_batch_memory`).
        On a GPU the default chunk is sized to its free memory (up to 2²⁰ ICs).
    device
        ``"cpu"``, ``"cuda"`` (a GPU through numba-cuda, ``pip
        install 'dicetrace[cuda]'``; a :class:`~dicetrace.devices.DeviceError`
        where there is none) or ``"auto"`` (the GPU where there is one; one
        line on standard error says which).  The GPU runs the same kernels
        compiled for the device with the CPU's arithmetic: throws as on the
        CPU up to the last ulp of the device's sin, cos and exp (docs/gpu.md).
        The result records it (``BatchResult.device``).
        None (default): :func:`~dicetrace.devices.default_device`, the CPU
        unless a :func:`~dicetrace.devices.use_device` block says otherwise.
        A :class:`~dicetrace.devices.Device` (what ``resolve_device``
        returns) is taken as it is, resolved already.
    record
        What to keep besides the summaries: None, or the exact contact events,
        ``Record.events_only()``, as :func:`simulate` keeps them
        (``BatchResult.set_times``); contact integrators only, on either
        device (the GPU runs the same events loop, docs/gpu.md).  The throws
        are those without events bit for bit, and on the CPU the batch is
        bit-identical to :func:`simulate` with events, row by row.  A batch
        keeps no per-step trace: a record that asks for trace channels is
        refused (ValueError).

    orientations, heights_cm
        A full starting state per throw: its orientation, (m, 4) unit
        quaternions x, y, z, w (world from body) or (m, 3, 3) rotation
        matrices, and the start height of its centre of mass, cm (one number
        or m); None: the preset's start (face 3 down, at ``z0_cm``) for every
        throw.  Each throw is then that of :func:`simulate` with
        ``orientation=`` its matrix (and ``z0_cm=`` its height), bit for bit;
        the throws run one per numba thread (CPU only), and the result keeps
        them (``BatchResult.orientations``, ``heights_cm``; the tables'
        columns ``qx, qy, qz, qw, z0_cm``).  A throw whose die would start
        below the ground is refused, naming it.
    events
        Deprecated: ``events=True`` is ``record=Record.events_only()``; it
        warns, and goes in the next release.

    Integer arguments may be Python or numpy integers; bools, floats and
    anything else are refused with a ValueError naming the argument, as are
    ICs that are not real numbers (complex, bool, text, other objects).
    """
    cfg = resolve_config(config, **options)
    cap = _integer(cap, "cap", 1, MAX_CAP)
    threads = _integer(threads, "threads", 1, none_ok=True)
    chunk = _integer(chunk, "chunk", 1, none_ok=True)
    if device is not None and not isinstance(device, Device):
        check_device(device)  # the name, now; what it names is resolved once the inputs have passed their checks
    record = summary_record(record_with_events(record, events, "simulate_batch"))
    events = check_events(cfg, wants_events(record), "record=Record(events=True)")
    conv = cfg.preset.l_convention if l_convention is None else l_convention
    coords = ics.coords if isinstance(ics, SliceICs) else None
    ics = validate_ics(ics)
    m = len(ics)
    if coords is not None:
        coords = np.array(coords, dtype=np.float64).reshape(m, 3)
    cfg.to_preset_convention(ics[:0], conv)  # a bad l_convention is refused before anything runs
    posed = orientations is not None or heights_cm is not None
    if posed:
        rots, heights, offsets = _poses(cfg, orientations, heights_cm, m)
    device = resolve_device(device)  # once: everything below takes this Device
    if posed and device.gpu:
        raise ValueError("orientations and heights_cm: throws from their own poses run on the CPU (device='cpu')")
    if posed:
        chunk = 1  # one throw a chunk: each has its own starting offsets and height
    if chunk is None:
        chunk = gpu_batch_chunk(cfg.kernel_inputs(ics[:0]), cap, record) if device.gpu else batch_chunk(cap, record)
    check_batch_memory(m, cap, chunk, ics_copy=conv != cfg.preset.l_convention, record=record)
    status, outcome = np.zeros(m, dtype=np.int8), np.zeros(m, dtype=np.int8)
    steps, nsets = np.zeros(m, dtype=np.int64), np.zeros(m, dtype=np.int64)
    set_parts: list[np.ndarray] = []
    step_parts: list[np.ndarray] = []
    time_parts: list[np.ndarray] = []
    bounds = [(a, min(m, a + chunk)) for a in range(0, m, chunk)]

    def one_chunk(a: int, b: int):
        return run_chunk(cfg.kernel_inputs(ics[a:b], l_convention=conv), cap, threads, device, record)

    if posed:
        results = _posed_results(cfg, ics, conv, offsets, heights, cap, threads, record)
    else:
        results = chunk_results(bounds, one_chunk, device)
    # chunk by chunk (on several GPUs, a few at a time): one chunk's buffers in memory, its sets compacted
    for (a, b), (st, sp, oc, ns, sets, set_steps, times) in zip(bounds, results):
        status[a:b], steps[a:b], outcome[a:b], nsets[a:b] = st, sp, oc, ns
        set_parts.append(sets)
        step_parts.append(set_steps)
        if times is not None:
            time_parts.append(times)
        del sets, set_steps, times
    offsets = np.zeros(m + 1, dtype=np.int64)
    np.cumsum(nsets, out=offsets[1:])
    del nsets
    total = int(offsets[-1])
    flat_sets = join_parts(set_parts, np.uint8, total) if set_parts else np.zeros(0, dtype=np.uint8)
    flat_steps = join_parts(step_parts, np.int32, total) if step_parts else np.zeros(0, dtype=np.int32)
    flat_times = None
    if events:
        flat_times = join_parts(time_parts, np.float64, total) if time_parts else np.zeros(0, dtype=np.float64)
    return BatchResult(
        ics=cfg.to_preset_convention(ics, conv),
        outcome=outcome,
        status_code=status,
        steps=steps,
        t_settle_s=steps * cfg.numerics.dt_s,
        set_offsets=offsets,
        sets=flat_sets,
        set_steps=flat_steps,
        config=cfg,
        coords=coords,
        device=device.label,
        set_times=flat_times,
        orientations=_pose_quaternions(orientations, rots, m) if posed else None,
        heights_cm=heights if posed else None,
    )


def _pose_quaternions(orientations, rots: np.ndarray, m: int) -> np.ndarray:
    """The quaternions (m, 4), x, y, z, w, a posed batch's table keeps: the ones given, as given, so that a throw
    replayed from its row (``record --rolls``) starts from the very rotation it ran from (a quaternion read off
    that rotation again differs in its last bits for most throws, and so does the rotation made from it); read
    off the rotations where matrices were given (or none: the identity).  A quaternion with w < 0 is kept as −q
    (w ≥ 0, as scipy's canonical form): the same rotation to the last bit, since R(q) is quadratic in q."""
    if orientations is not None:
        q = np.array(orientations, dtype=np.float64)
        if q.shape == (m, 4):
            q[q[:, 3] < 0] *= -1.0
            return q
    return quaternions_xyzw(rots)


def _poses(cfg: Config, orientations, heights_cm, m: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The throws' orientations (m, 3, 3), start heights (m,) and starting node offsets (m, 8, 3), checked: every
    die starts on or above the ground.  Each throw's offsets are ``cfg.initial_offsets(R)``'s arithmetic, the
    body's offsets turned by R, without checking R again (``validate_orientations`` did)."""
    rots = np.broadcast_to(np.eye(3), (m, 3, 3)) if orientations is None else validate_orientations(orientations, m)
    heights = np.full(m, cfg.preset.z0_cm) if heights_cm is None else validate_heights(heights_cm, m)
    body_off = cfg.initial_offsets()
    offsets = np.stack([body_off @ r.T for r in rots]) if m else np.zeros((0, 8, 3))
    lowest = heights + offsets[:, :, 2].min(axis=1)  # each throw's lowest node
    bad = np.flatnonzero(lowest < 0.0)
    if len(bad):
        i = int(bad[0])
        raise ValueError(f"throw {i} starts below the ground: its lowest node is at {lowest[i]:.6g} cm (height "
                         f"{heights[i]:.6g} cm); raise its height")
    return np.ascontiguousarray(rots), heights, offsets


def _posed_results(cfg: Config, ics, conv, offsets, heights, cap: int, threads, record: Record | None):
    """Each throw from its own starting offsets and height (:func:`_poses`), one per numba thread (the kernels release
    the GIL): its results in order."""
    import numba

    from dicetrace.params import KernelInputs

    kin = cfg.kernel_inputs(ics, l_convention=conv)

    def one(i: int):
        k = KernelInputs(kin.ics[i : i + 1], offsets[i], kin.params._replace(z0_cm=float(heights[i])), kin.integrator_id)
        return run_chunk(k, cap, 1, CPU_DEVICE, record)

    workers = numba.get_num_threads() if threads is None else max(1, min(int(threads), numba.config.NUMBA_NUM_THREADS))
    from concurrent.futures import ThreadPoolExecutor

    with ThreadPoolExecutor(max_workers=workers) as pool:
        yield from pool.map(one, range(len(ics)))
