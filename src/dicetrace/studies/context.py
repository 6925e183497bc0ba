"""What every writeup study shares: run options, the compute context and the render output.

A study module (``dicetrace.studies.study_cells`` ...) has ``compute(ctx)`` and
``render(computed, out)``:

- ``compute(ctx: Context) -> Computed`` simulates and measures.  It gets the
  options, the grid sizes (``ctx.res``, ``ctx.pick``), a seeded RNG and
  cached grids (``ctx.sample``); it returns the numbers that go into
  ``results/<study>.json`` (``Computed.results``) and the arrays its figures
  need (``Computed.plot``), and imports no plotting library.
- ``render(computed, out: Output)`` draws the figures (small palette PNGs,
  < 300 KB), writes CSV files and the Markdown tables of the report; it
  changes no number.

:func:`dicetrace.studies.runner.run` chains the two and writes the JSON.
"""

from __future__ import annotations

import hashlib
import io
import json
import math
import os
import sys
import time
import warnings
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from dicetrace.compile_clock import CompileClock, rate_text
from dicetrace.studies.outputs import label_axes, write_text, written
from dicetrace.windows import get_window

#: Default seed of the studies' perturbations and random picks.
DEFAULT_SEED = 20191001
#: Largest figure file written (bytes); figures are re-saved at lower dpi until they fit.
MAX_FIG_BYTES = 290_000
#: The writeup's eight windows (names in ``dicetrace.ics.WINDOWS``), in the writeup's order.
WRITEUP_WINDOWS = ("home", "zoom-out", "more-out", "most-out", "red-sea", "red-sea-2", "party", "green-island")


@dataclass(frozen=True)
class Options:
    """How a study runs: ``quick`` (CI-sized grids), ``res`` (override of the main grid), the seed, the cache.

    ``integrator`` and ``tol`` override the integrator and tolerance of the
    converged models (study k, :mod:`dicetrace.studies.study_converged`); the
    other studies ignore them.  ``device``: where every batch of the run goes
    (a name, or a :class:`~dicetrace.devices.Device` resolved already; the
    runner resolves it once and sets it for the whole run).
    """

    quick: bool = False
    res: int | None = None
    seed: int = DEFAULT_SEED
    no_cache: bool = False
    integrator: str | None = None
    tol: float | None = None
    device: object = "cpu"

    @property
    def full(self) -> bool:
        """The committed results' settings: full size, default grid, seed and integrators."""
        return (not self.quick and self.res is None and self.seed == DEFAULT_SEED and self.integrator is None
                and self.tol is None)


@dataclass
class Computed:
    """What ``compute`` returns: JSON-able ``results`` and the figures' data ``plot`` (not written)."""

    results: dict
    plot: dict = field(default_factory=dict)


def window_ranges(window) -> tuple[tuple[float, float], ...]:
    """Ranges of a window: a name in ``dicetrace.ics.WINDOWS``, or ranges (returned as tuples)."""
    if isinstance(window, str):
        return get_window(window, 2)
    return tuple((float(a), float(b)) for a, b in window)


class Context:
    """What ``compute`` gets: options, sizes, a seeded RNG, simulations cached in ``cache_dir``, a log."""

    def __init__(self, name: str, options: Options, cache_dir: Path):
        self.name = name
        self.options = options
        self.quick = bool(options.quick)
        self.cache_dir = Path(cache_dir)
        self.cache_dir.mkdir(parents=True, exist_ok=True)
        self.rng = np.random.default_rng(options.seed)
        self.t0 = time.perf_counter()
        self.n_throws = 0

    def res(self, full: int, quick: int) -> int:
        """The main grid size: ``--res`` if given, else ``quick`` or ``full``."""
        if self.options.res is not None:
            return int(self.options.res)
        return quick if self.quick else full

    def pick(self, full, quick):
        return quick if self.quick else full

    def log(self, msg: str) -> None:
        print(f"[{self.name} {time.perf_counter() - self.t0:7.1f}s] {msg}", flush=True)

    def sample(self, window, res, *, slice_spec="seed", sequences=False, **overrides):
        """:func:`dicetrace.analysis.simulator.sample_window`, cached in the cache folder."""
        from dicetrace.analysis.simulator import sample_window  # lazy: keeps `dicetrace --help` fast (imports numba)
        from dicetrace.core._jit import kernel_digest

        win = window_ranges(window)
        res_t = (int(res),) * len(win) if np.isscalar(res) else tuple(int(r) for r in res)
        key = [slice_spec, win, res_t, bool(sequences), sorted(overrides.items()), _resolved(overrides), kernel_digest()]
        label = str(self.options.device)  # a Device's label, or the name
        if label != "cpu":  # a GPU's grid may differ from the CPU's by rounding: cached apart
            key.append(label)
        key = json.dumps(key, sort_keys=True)
        path = self.cache_dir / f"{hashlib.sha1(key.encode()).hexdigest()[:16]}.npz"
        if path.exists() and not self.options.no_cache:
            cached = read_cached_sample(path, key, win, res_t, sequences)
            if not isinstance(cached, str):
                return cached
            print(f"dicetrace: warning: cache file {str(path)!r} ignored ({cached}): simulating its grid again",
                  file=sys.stderr, flush=True)
        with CompileClock() as clock:  # a first run's compiling is told apart from the throws' own time
            s = sample_window(win, res_t, slice_spec=slice_spec, sequences=sequences, **overrides)
        self.n_throws += s.labels.size
        write_cached_sample(path, key, s)
        self.log(f"simulated {window if isinstance(window, str) else win} at {res_t} "
                 f"({rate_text(s.labels.size, 'throws', s.wall_s, clock.seconds)})")
        return s


#: Version of the grid cache's file layout (a file of another layout is ignored and simulated again).
CACHE_FORMAT = 2
#: The arrays of a cached grid besides its axes (``axis0``...): numbers only, never Python objects.
_CACHE_ARRAYS = ("labels", "t_settle_s", "status_code", "wall_s", "seq_bytes", "seq_offsets")


def write_cached_sample(path: Path, key: str, s) -> None:
    """Write a simulated grid to ``path`` (``.npz``) as plain arrays only: numbers, the key as a byte string,
    the contact sequences as UTF-8 bytes and offsets; readable with ``allow_pickle=False``.  Atomic: a
    temporary file renamed into place, so that a reader never sees half a file."""
    if s.sequences is not None:
        encoded = [str(q).encode("utf-8") for q in np.asarray(s.sequences, dtype=object).ravel()]
        seq_bytes = np.frombuffer(b"".join(encoded), dtype=np.uint8)
        seq_offsets = np.concatenate([[0], np.cumsum([len(b) for b in encoded], dtype=np.int64)]).astype(np.int64)
    else:
        seq_bytes, seq_offsets = np.zeros(0, np.uint8), np.zeros(0, np.int64)
    arrays = {
        "format": np.int64(CACHE_FORMAT),
        "key": np.frombuffer(key.encode("utf-8"), dtype=np.uint8),
        "labels": np.asarray(s.labels), "t_settle_s": np.asarray(s.t_settle_s, dtype=np.float64),
        "status_code": np.asarray(s.status_code), "wall_s": np.float64(s.wall_s),
        "seq_bytes": seq_bytes, "seq_offsets": seq_offsets,
        **{f"axis{i}": np.asarray(a, dtype=np.float64) for i, a in enumerate(s.axes)},
    }
    if any(np.asarray(a).dtype.hasobject for a in arrays.values()):  # pragma: no cover - a defect, never written
        raise TypeError("a cached grid holds only numeric arrays")
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        with open(tmp, "wb") as f:
            np.savez(f, **arrays)
        os.replace(tmp, path)
    except OSError as e:  # a cache that cannot be written costs a later run time, never this run
        tmp.unlink(missing_ok=True)
        print(f"dicetrace: warning: cannot write cache file {str(path)!r} ({e.strerror or e}): the grid is not "
              "cached", file=sys.stderr, flush=True)


def read_cached_sample(path: Path, key: str, window, res_t: tuple, sequences: bool):
    """The grid cached in ``path`` if it is one of ``key``, else the reason it is not (a string).

    Read with ``allow_pickle=False``: a file holding Python objects (a pickle, an object array) is refused
    by numpy before anything in it is run.  A file that does not load, is of another layout or key, or whose
    arrays do not have the grid's shape is not used."""
    from dicetrace.analysis.simulator import WindowSample  # lazy: keeps `dicetrace --help` fast (imports numba)

    try:
        with np.load(path, allow_pickle=False) as z:
            names = set(z.files)
            need = {"format", "key", *_CACHE_ARRAYS, *(f"axis{i}" for i in range(len(res_t)))}
            if "format" not in names:
                return "not a grid of this cache's layout (an older dicetrace's, or another file)"
            if not need <= names:
                return "not a grid of this dicetrace's cache: " + ", ".join(sorted(need - names)) + " missing"
            if int(z["format"]) != CACHE_FORMAT:
                return f"cache layout {int(z['format'])}, not {CACHE_FORMAT}"
            if z["key"].dtype != np.uint8 or z["key"].tobytes() != key.encode("utf-8"):
                return "a grid of another configuration"
            arrays = {k: z[k] for k in need - {"format", "key"}}
    except (OSError, ValueError, EOFError, zipfile.BadZipFile, KeyError, TypeError, AttributeError) as e:
        # AttributeError: a file that np.load reads as a plain array (.npy, not a zip of arrays) has no .files
        why = (e.strerror if isinstance(e, OSError) else None) or (str(e).splitlines() or [type(e).__name__])[0]
        return f"unreadable: {why[:160]}"
    labels = arrays["labels"]
    shapes_ok = (labels.shape == tuple(res_t) and arrays["t_settle_s"].shape == labels.shape
                 and arrays["status_code"].shape == labels.shape
                 and all(arrays[f"axis{i}"].shape == (r,) for i, r in enumerate(res_t)))
    seq = None
    if shapes_ok and sequences:
        offsets, raw = arrays["seq_offsets"], arrays["seq_bytes"]
        shapes_ok = (offsets.shape == (labels.size + 1,) and raw.dtype == np.uint8 and offsets[0] == 0
                     and offsets[-1] == raw.size and bool(np.all(np.diff(offsets) >= 0)))
        if shapes_ok:
            data = raw.tobytes()
            try:
                seq = np.empty(labels.size, dtype=object)
                seq[:] = [data[a:b].decode("utf-8") for a, b in zip(offsets[:-1].tolist(), offsets[1:].tolist())]
            except UnicodeDecodeError:
                return "contact sequences that are not UTF-8"
            seq = seq.reshape(labels.shape)
    if not shapes_ok:
        return "arrays not of the grid's shape"
    return WindowSample(labels=labels, t_settle_s=arrays["t_settle_s"], axes=[arrays[f"axis{i}"] for i in range(len(res_t))],
                        window=window, sequences=seq, status_code=arrays["status_code"],
                        wall_s=float(arrays["wall_s"]))

def _resolved(overrides: dict) -> dict:
    """The whole configuration a sample with these options runs (so that a cached grid is never one of an
    older default: a preset's tolerance, a Numerics default)."""
    from dicetrace.analysis.simulator import _resolve_config  # lazy: keeps `dicetrace --help` fast (imports numba)

    opts = dict(overrides)
    preset = opts.pop("preset", "seed")  # sample_window's default
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # make_config's own warnings belong to the run, not to its cache key
        return _resolve_config(None, preset, opts).as_dict()


class Output:
    """What ``render`` gets: the output folder, figure and CSV writers, and the report's tables."""

    def __init__(self, out_dir: Path):
        import matplotlib  # matplotlib is slow to import: only when rendering

        matplotlib.use("Agg")
        self.out = Path(out_dir)
        self.fig_dir = self.out / "figures"
        self.res_dir = self.out / "results"
        for d in (self.fig_dir, self.res_dir):
            d.mkdir(parents=True, exist_ok=True)
        self.figures: dict = {}
        self.tables: dict = {}

    def save_fig(self, fig, name: str, *, key: str | None = None, caption: str = "") -> str:
        """Save a figure as a small palette PNG (< 300 KB); returns the path relative to the output folder."""
        import matplotlib.pyplot as plt  # matplotlib and PIL: only when drawing
        from PIL import Image

        path = self.fig_dir / f"{name}.png"
        dpi = fig.dpi
        for _ in range(6):
            buf = io.BytesIO()
            fig.savefig(buf, format="png", dpi=dpi)
            buf.seek(0)
            img = Image.open(buf).convert("RGB")
            pal = img.quantize(colors=96, method=Image.Quantize.MEDIANCUT, dither=Image.Dither.NONE)
            png = io.BytesIO()
            pal.save(png, format="PNG", optimize=True)
            if png.tell() <= MAX_FIG_BYTES:
                break
            dpi *= 0.8
        with written(path, "figure") as tmp:
            tmp.write_bytes(png.getvalue())
        plt.close(fig)
        rel = f"figures/{name}.png"
        self.add_file(rel, key or name, caption)
        return rel

    def save_plot(self, fig, ax, name: str, *, xlabel: str, ylabel: str, title: str, caption: str,
                  legend: int | bool | None = 7, title_size: float | None = None) -> str:
        """Label one axes (:func:`~dicetrace.studies.outputs.label_axes`), lay out, :meth:`save_fig`."""
        label_axes(ax, xlabel=xlabel, ylabel=ylabel, title=title, legend=legend, title_size=title_size)
        fig.tight_layout()
        return self.save_fig(fig, name, caption=caption)

    def add_file(self, rel: str, key: str, caption: str = "") -> None:
        """Register a file written under the output folder as figure ``key`` of the report."""
        p = self.out / rel
        self.figures[key] = {"path": rel, "caption": caption, "bytes": p.stat().st_size if p.exists() else None}

    def write_csv(self, df, name: str) -> str:
        with written(self.res_dir / f"{name}.csv", "table") as tmp:
            df.to_csv(tmp, index=False)
        return f"results/{name}.csv"


def rerender_results(out, name: str, render, derive=None) -> dict:
    """Draw a study's figures and tables again from ``OUT/results/NAME.json`` alone and write them back into it: no
    simulation, no measured number changed.  ``derive(r)``, when given, first derives again in place what is a pure
    function of the stored numbers (with the code as it is now); ``render(Computed(r), Output(OUT))`` draws."""
    path = Path(out) / "results" / f"{name}.json"
    r = json.loads(path.read_text())
    if derive is not None:
        derive(r)
    output = Output(Path(out))
    render(Computed(r), output)
    r["figures"], r["tables"] = output.figures, output.tables
    write_json(path, r)
    return r


def write_json(path: Path, obj) -> Path:
    """Write ``obj`` (numpy types converted, NaN as null) atomically (:func:`~dicetrace.studies.outputs.written`)."""
    return write_text(path, json.dumps(jsonable(obj), indent=1, sort_keys=False), "results file")


def jsonable(obj):
    """Plain Python types for json.dump (numpy scalars/arrays, tuples, NaN -> None)."""
    if isinstance(obj, dict):
        return {str(k): jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return jsonable(obj.tolist())
    if isinstance(obj, (np.bool_, bool)):
        return bool(obj)
    if isinstance(obj, (np.integer,)):
        return int(obj)
    if isinstance(obj, (np.floating, float)):
        v = float(obj)
        return v if math.isfinite(v) else None
    if obj is None or isinstance(obj, (str, int)):
        return obj
    return str(obj)
