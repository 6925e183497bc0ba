"""What a scan is: an IC space, a configuration, a chunk size, the device its throws run on, and whether its rows
hold exact contact events.

A :class:`ScanDefinition` fully determines a scan's rows (the device to
rounding: a GPU's throws of the contact schemes may differ from the CPU's in
the last bits, so a scan runs on one device from start to end).  It is stored
(as JSON) in the dataset's manifest and in every chunk file's metadata,
compared on resume, and shipped to Dask workers as a plain dict.
"""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import dataclass

import numpy as np

from dicetrace.ics import MAX_AXIS_POINTS, MAX_ICS, Grid, IcSpace, Points, Sample, space_from_dict
from dicetrace.params import Config, ConfigError, Numerics, Preset, _show
from dicetrace.saving import Record
from dicetrace.scan.poses import POSED_KINDS, HandThrows, ThrowTable, posed_from_dict, space_l_convention

FORMAT = "dicetrace-scan/1"
#: ICs per chunk (one Parquet file, one Dask task): ~0.3 s of work on one core.
DEFAULT_CHUNK = 8192
#: ICs per chunk of a new scan on a GPU: one kernel launch each, enough threads to fill a large GPU (an H200
#: keeps ~270,000 resident) and ~170 MB of contact-set buffers.
GPU_DEFAULT_CHUNK = 2**18
#: Largest chunk: one chunk's buffers are held in memory (about 1 KiB per IC: 16 GiB).
MAX_CHUNK = 1 << 24


#: The device of a definition stored without one (every scan before GPUs ran on the CPU).
DEFAULT_DEVICE = "cpu"
#: What a definition stored without a word on events records (every scan before events: the sets at step ends).
DEFAULT_EVENTS = False


def device_kind(label: str) -> str:
    """``"cpu"`` or ``"cuda"``: what ``simulate_batch(device=...)`` asks for to run on the device ``label``."""
    return "cpu" if label == "cpu" else "cuda"


def config_from_dict(d: dict) -> Config:
    """Inverse of ``Config.as_dict()``: a configuration read back (a manifest, a Dask task) passes the same
    checks, :class:`~dicetrace.params.Preset`'s and :class:`~dicetrace.params.Numerics`', as one built anew."""
    return Config(preset=Preset(**d["preset"]), numerics=Numerics(**d["numerics"]))


@dataclass(frozen=True)
class ScanDefinition:
    """An IC space scanned with one configuration, in chunks of ``chunk`` ICs, on ``device``.

    Chunk c holds the ICs with ``ic_id`` in ``[c·chunk, min((c+1)·chunk, size))``.
    ``device``: where the throws run, as :func:`dicetrace.devices.device_label`
    says it: ``"cpu"`` or ``"cuda: <GPU name>"`` (a resolved device, never
    ``"auto"``: :func:`~dicetrace.scan.scan` resolves its ``device`` argument).
    ``events``: the rows hold the exact contact events (``simulate_batch(...,
    record=Record.events_only())``: the contact sets inside the sub-steps and
    a column ``contact_times_s``); the contact integrators only.  It is the
    definition's stored form (a boolean in its JSON, absent in a folder
    written before scans held events: False); :attr:`record` is the request
    its chunks pass on.
    ``space`` may also be a space of full starting states
    (:mod:`dicetrace.scan.poses`: hand throws drawn from a model, or a throw
    table's rows), whose rows add the pose columns ``qx, qy, qz, qw, z0_cm``;
    such throws run on the CPU.  The die is the configuration's
    (``config.preset.body``: any box, loaded or not); :attr:`die` says it.
    """

    space: IcSpace
    config: Config
    chunk: int = DEFAULT_CHUNK
    device: str = DEFAULT_DEVICE
    events: bool = DEFAULT_EVENTS

    def __post_init__(self) -> None:
        if not isinstance(self.space, (Grid, Sample, Points, HandThrows, ThrowTable)):
            raise TypeError(f"space must be a Grid, Sample or Points (dicetrace.ics), or HandThrows or ThrowTable "
                            f"(dicetrace.scan.poses), not {type(self.space).__name__}")
        if not isinstance(self.config, Config):
            raise TypeError(f"config must be a dicetrace.params.Config, not {type(self.config).__name__}")
        c = self.chunk
        if (isinstance(c, bool) or not isinstance(c, (int, float, np.integer, np.floating))
                or not math.isfinite(c) or int(c) != c or c < 1):
            raise ConfigError("chunk", f"chunk must be an integer >= 1, got {_show(c)}")
        if int(c) > MAX_CHUNK:
            raise ConfigError("chunk", f"chunk must be at most {MAX_CHUNK:,} ICs (one chunk is held in memory), got {int(c):,}")
        object.__setattr__(self, "chunk", int(c))
        d = self.device
        if not isinstance(d, str) or not (d == "cpu" or (d.startswith("cuda: ") and d[6:].strip())):
            raise ConfigError("device", f"device must be 'cpu' or 'cuda: <GPU name>' (a resolved device), got {_show(d)}")
        if not isinstance(self.events, (bool, np.bool_)):
            raise ConfigError("events", f"events must be True or False, got {_show(self.events)}")
        object.__setattr__(self, "events", bool(self.events))
        if self.events:
            from dicetrace.simulate import check_events  # lazy: numba; only a scan with events asks

            try:
                check_events(self.config, True)
            except ValueError as e:
                raise ConfigError("events", str(e)) from None
        if self.posed and self.device != "cpu":
            raise ConfigError("device", f"throws from their own poses ({self.space.kind}) run on the CPU, not on "
                              f"{self.device}")
        size = self.space.size
        what = {"grid": "res", "sample": "n", "throws": "n"}.get(self.space.kind, "points")  # what sets the size
        if size > MAX_ICS:
            raise ConfigError(
                what, f"the space has {size:,} ICs ({size:.3g}): more than a scan can number (ic_id is int64, at most {MAX_ICS:.3g})"
            )
        if isinstance(self.space, Grid) and max(self.space.res) > MAX_AXIS_POINTS:
            raise ConfigError(
                "res", f"the grid has {max(self.space.res):,} points on an axis: a scan takes at most {MAX_AXIS_POINTS:,} "
                "(grid indices are int32)"
            )

    @property
    def size(self) -> int:
        return self.space.size

    @property
    def record(self) -> Record | None:
        """What the scan's throws keep besides their summaries, as ``simulate_batch(record=...)`` takes it:
        ``Record.events_only()`` for a scan of exact events, else None (a scan keeps no per-step trace)."""
        return Record.events_only() if self.events else None

    @property
    def posed(self) -> bool:
        """Whether each throw starts from its own pose (a space of :mod:`dicetrace.scan.poses`)."""
        return isinstance(self.space, (HandThrows, ThrowTable))

    @property
    def l_convention(self) -> str:
        """The L convention of the ICs the space gives (converted to the preset's before the throws)."""
        return space_l_convention(self.space, self.config) if self.posed else self.space.slice.l_convention

    def block(self, start: int, stop: int):
        """The ICs ``start..stop-1`` (an :class:`~dicetrace.ics.IcBlock`, or a
        :class:`~dicetrace.scan.poses.PosedBlock` with each throw's orientation and height)."""
        return self.space.block(start, stop, self.config) if self.posed else self.space.block(start, stop)

    @property
    def die(self) -> dict:
        """The die the throws are of, as the tables' metadata says it: its sides and half-extents (cm), the share
        of its mass in a load and where (cm, body frame, from the box's centre), its centre of mass."""
        return die_dict(self.config.preset)

    @property
    def n_chunks(self) -> int:
        return -(-self.size // self.chunk)

    def chunk_range(self, c: int) -> tuple[int, int]:
        if isinstance(c, bool) or not isinstance(c, (int, np.integer)) or not 0 <= c < self.n_chunks:
            raise ValueError(f"chunk {c} outside 0..{self.n_chunks - 1}")
        c = int(c)
        return c * self.chunk, min(self.size, (c + 1) * self.chunk)

    def to_dict(self) -> dict:
        return {"format": FORMAT, "space": self.space.to_dict(), "config": self.config.as_dict(), "chunk": self.chunk,
                "device": self.device, "events": self.events}

    @classmethod
    def from_dict(cls, d: dict) -> "ScanDefinition":
        """Inverse of :meth:`to_dict` (a definition stored before scans recorded their device ran on the CPU, and
        one stored before scans could hold events holds none)."""
        if d.get("format") != FORMAT:
            raise ValueError(f"not a {FORMAT} scan definition (format {d.get('format')!r})")
        space = d["space"]
        space = posed_from_dict(space) if space.get("kind") in POSED_KINDS else space_from_dict(space)
        return cls(space, config_from_dict(d["config"]), d["chunk"], d.get("device", DEFAULT_DEVICE),
                   d.get("events", DEFAULT_EVENTS))

    @property
    def schema(self):
        """The Arrow schema of the scan's rows: ``GRID_ROLLS_SCHEMA``, with ``contact_times_s`` where it holds
        exact contact events, then ``qx, qy, qz, qw, z0_cm`` where its throws start from their own poses."""
        from dicetrace.tables import GRID_ROLLS_EVENTS_SCHEMA, GRID_ROLLS_SCHEMA, POSE_FIELDS  # lazy: pyarrow

        schema = GRID_ROLLS_EVENTS_SCHEMA if self.events else GRID_ROLLS_SCHEMA
        for f in POSE_FIELDS if self.posed else ():
            schema = schema.append(f)
        return schema

    def canonical(self) -> str:
        """Canonical JSON: :meth:`to_dict` with sorted keys (made once per definition: a scan of points holds
        every point)."""
        text = self.__dict__.get("_canonical")
        if text is None:
            text = self.__dict__["_canonical"] = json.dumps(self.to_dict(), sort_keys=True)  # frozen: not setattr
        return text

    def digest(self) -> str:
        """SHA-256 of :meth:`canonical` (a short key for the definition)."""
        text = self.__dict__.get("_digest")
        if text is None:
            text = self.__dict__["_digest"] = hashlib.sha256(self.canonical().encode()).hexdigest()
        return text


def die_dict(preset: Preset) -> dict:
    """The die of ``preset`` for a table's metadata (see :attr:`ScanDefinition.die`)."""
    body = preset.body
    return {"sides_cm": [2.0 * v for v in body.half_extents_cm], "half_extents_cm": list(body.half_extents_cm),
            "load_fraction": body.load_fraction, "load_cm": list(body.load_cm),
            "com_cm": [float(v) for v in body.com_cm], "cube": body.is_cube}


def as_written_now(d):
    """A stored definition dict as this version writes it (what compares on resume): one stored before scans
    recorded their device gets ``"device": "cpu"``, one stored before scans could hold events ``"events":
    False``; anything else as it is."""
    if isinstance(d, dict) and d.get("format") == FORMAT:
        return {"device": DEFAULT_DEVICE, "events": DEFAULT_EVENTS, **d}
    return d


def _same(a, b) -> bool:
    """Whether two JSON values are the same value: numbers by value (``0`` is ``0.0``), a boolean only a boolean,
    lists element by element, objects key by key, anything else by type and value."""
    if isinstance(a, bool) or isinstance(b, bool):
        return isinstance(a, bool) and isinstance(b, bool) and a == b
    if isinstance(a, (int, float)) and isinstance(b, (int, float)):
        return a == b
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    return type(a) is type(b) and a == b


def describe_differences(a, b, prefix: str = "") -> list[str]:
    """Where two definition dicts differ, by value (a number written ``0`` or ``0.0`` is the same number): each
    place a human-readable path with both values (for refusals); empty when they are the same definition."""
    out: list[str] = []
    if isinstance(a, dict) and isinstance(b, dict):
        for k in sorted(set(a) | set(b), key=str):
            p = f"{prefix}.{k}" if prefix else str(k)
            if k not in a or k not in b:
                out.append(f"{p}: {_short(a[k]) if k in a else '(absent)'} vs {_short(b[k]) if k in b else '(absent)'}")
            else:
                out += describe_differences(a[k], b[k], p)
    elif not _same(a, b):
        out.append(f"{prefix or '(the whole definition)'}: {_short(a)} vs {_short(b)}")
    return out


def _short(v) -> str:
    text = json.dumps(v, default=repr)
    return text if len(text) <= 60 else text[:57] + "..."


def same_definition(a, b) -> bool:
    """Whether two stored definition dicts are the same scan (:func:`as_written_now` applied to both): their
    values compared, not their text."""
    return not describe_differences(as_written_now(a), as_written_now(b))
