"""What every writeup study shares: run options, the compute context and the render output.

A study module (``dicetrace.studies.cells`` ...) has ``compute(ctx)`` and
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
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

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
    converged models (study k, :mod:`dicetrace.studies.converged`); the
    other studies ignore them.
    """

    quick: bool = False
    res: int | None = None
    seed: int = DEFAULT_SEED
    no_cache: bool = False
    integrator: str | None = None
    tol: float | None = None

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
    from dicetrace.ics import get_window

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
        from dicetrace.analysis.simulator import WindowSample, sample_window
        from dicetrace.core._jit import kernel_digest

        win = window_ranges(window)
        res_t = (int(res),) * len(win) if np.isscalar(res) else tuple(int(r) for r in res)
        key = json.dumps([slice_spec, win, res_t, bool(sequences), sorted(overrides.items()),
                          _resolved(overrides), kernel_digest()], sort_keys=True)
        path = self.cache_dir / f"{hashlib.sha1(key.encode()).hexdigest()[:16]}.npz"
        if path.exists() and not self.options.no_cache:
            z = np.load(path, allow_pickle=True)
            return WindowSample(
                labels=z["labels"], t_settle_s=z["t_settle_s"], axes=[z[f"axis{i}"] for i in range(len(win))],
                window=win, sequences=z["sequences"] if sequences else None, status_code=z["status_code"],
                wall_s=float(z["wall_s"]),
            )
        s = sample_window(win, res_t, slice_spec=slice_spec, sequences=sequences, **overrides)
        self.n_throws += s.labels.size
        np.savez(path, labels=s.labels, t_settle_s=s.t_settle_s,
                 sequences=s.sequences if sequences else np.zeros(0), status_code=s.status_code,
                 wall_s=s.wall_s, **{f"axis{i}": a for i, a in enumerate(s.axes)})
        self.log(f"simulated {window if isinstance(window, str) else win} at {res_t} "
                 f"({s.labels.size} throws, {s.wall_s:.1f} s, {s.labels.size / max(s.wall_s, 1e-9):.0f}/s)")
        return s


def _resolved(overrides: dict) -> dict:
    """The whole configuration a sample with these options runs (so that a cached grid is never one of an
    older default: a preset's tolerance, a Numerics default)."""
    import warnings

    from dicetrace.analysis.simulator import _resolve_config

    opts = dict(overrides)
    preset = opts.pop("preset", "seed")  # sample_window's default
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # make_config's own warnings belong to the run, not to its cache key
        return _resolve_config(None, preset, opts).as_dict()


class Output:
    """What ``render`` gets: the output folder, figure and CSV writers, and the report's tables."""

    def __init__(self, out_dir: Path):
        import matplotlib

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
        import matplotlib.pyplot as plt
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
        path.write_bytes(png.getvalue())
        plt.close(fig)
        rel = f"figures/{name}.png"
        self.add_file(rel, key or name, caption)
        return rel

    def save_plot(self, fig, ax, name: str, *, xlabel: str, ylabel: str, title: str, caption: str,
                  legend: int | bool | None = 7, title_size: float | None = None) -> str:
        """Label one axes (x, y, title; a legend of that font size, True: default size), lay out, :meth:`save_fig`."""
        ax.set_xlabel(xlabel)
        ax.set_ylabel(ylabel)
        ax.set_title(title, **({} if title_size is None else {"fontsize": title_size}))
        if legend is True:
            ax.legend()
        elif legend:
            ax.legend(fontsize=legend)
        fig.tight_layout()
        return self.save_fig(fig, name, caption=caption)

    def add_file(self, rel: str, key: str, caption: str = "") -> None:
        """Register a file written under the output folder as figure ``key`` of the report."""
        p = self.out / rel
        self.figures[key] = {"path": rel, "caption": caption, "bytes": p.stat().st_size if p.exists() else None}

    def write_csv(self, df, name: str) -> str:
        df.to_csv(self.res_dir / f"{name}.csv", index=False)
        return f"results/{name}.csv"


def write_json(path: Path, obj) -> Path:
    """Write ``obj`` (numpy types converted, NaN as null) atomically."""
    path = Path(path)
    tmp = path.with_suffix(path.suffix + ".tmp")
    tmp.write_text(json.dumps(jsonable(obj), indent=1, sort_keys=False))
    os.replace(tmp, path)
    return path


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
