"""Shared plumbing of the study scripts in ``analysis/``.

Every study is a script ``analysis/<letter>_<name>.py`` with a ``main(argv)``
that parses the common options (``--quick``, ``--res``, ``--out``,
``--seed``), writes its figures to ``OUT/figures/`` and its numbers to
``OUT/results/<name>.json``. :class:`Study` holds that context, saves figures
small (palette PNG, < 300 KB), caches simulated windows under ``OUT/cache/``
(so that studies run one after the other share their grids) and writes the
JSON with numpy types converted.
"""

from __future__ import annotations

import argparse
import hashlib
import io
import json
import math
import os
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
MAX_FIG_BYTES = 290_000

#: The program's own named windows (its interactive scatter, ``interactiveScatter/scatters.pde``)
#: beyond the eight of the writeup: the zooms below party and green island.
PROGRAM_WINDOWS = {
    "party-2": ((0.0197, 0.0205), (0.0177, 0.0186)),
    "party-3": ((0.01975, 0.01984), (0.0182, 0.0183)),
    "green-island-2": ((0.057, 0.0576), (0.042, 0.044)),
    "green-island-3": ((0.05725, 0.0573), (0.04358, 0.04372)),
    "green-island-4": ((0.057266, 0.057274), (0.043615, 0.043635)),
    "green-island-5": ((0.057269, 0.0572702), (0.043621, 0.043625)),
    "green-island-6.2-4": ((0.057269466, 0.0572694705), (0.043622917, 0.043622924)),
}

#: The writeup's eight windows (docs/model.md §11), in the writeup's order.
WRITEUP_WINDOWS = ("home", "zoom-out", "more-out", "most-out", "red-sea", "red-sea-2", "party", "green-island")


def window_ranges(name_or_ranges):
    """((x0, x1), (y0, y1)) of a writeup window, a program window, or ranges."""
    from dicetrace.analysis.simulator import resolve_window

    if isinstance(name_or_ranges, str) and name_or_ranges in PROGRAM_WINDOWS:
        return PROGRAM_WINDOWS[name_or_ranges]
    return resolve_window(name_or_ranges, 2 if isinstance(name_or_ranges, str) else len(name_or_ranges))


def parser(description: str) -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description=description)
    p.add_argument("--quick", action="store_true", help="small grids (seconds), for CI")
    p.add_argument("--res", type=int, default=None, help="grid points per axis of the main 2-D grids")
    p.add_argument("--out", type=Path, default=HERE, help="output folder (figures/, results/); default analysis/")
    p.add_argument("--seed", type=int, default=20191001, help="random seed (perturbations, picks)")
    p.add_argument("--no-cache", action="store_true", help="re-simulate even if a cached grid exists")
    return p


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


def md_table(rows: list[dict], columns: list[tuple[str, str, str]]) -> str:
    """Markdown table: columns are (key, header, format spec or '' for str)."""
    head = "| " + " | ".join(h for _, h, _ in columns) + " |"
    sep = "|" + "|".join("---" for _ in columns) + "|"
    lines = [head, sep]
    for r in rows:
        cells = []
        for key, _, fmt in columns:
            v = r.get(key)
            if v is None or (isinstance(v, float) and not math.isfinite(v)):
                cells.append("–")
            elif fmt:
                try:
                    cells.append(format(v, fmt))
                except (TypeError, ValueError):
                    cells.append(str(v))
            else:
                cells.append(str(v))
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def pm(v, e, fmt=".3f") -> str:
    """'v ± e' with None/NaN shown as '–'."""
    if v is None or not math.isfinite(v):
        return "–"
    if e is None or not math.isfinite(e):
        return format(v, fmt)
    return f"{format(v, fmt)} ± {format(e, fmt)}"


class Study:
    """Context of one study run: options, output folders, figures, cache, results."""

    def __init__(self, name: str, args: argparse.Namespace):
        import matplotlib

        matplotlib.use("Agg")
        self.name = name
        self.args = args
        self.quick = bool(args.quick)
        self.out = Path(args.out)
        self.fig_dir = self.out / "figures"
        self.res_dir = self.out / "results"
        self.cache_dir = self.out / "cache"
        for d in (self.fig_dir, self.res_dir, self.cache_dir):
            d.mkdir(parents=True, exist_ok=True)
        self.rng = np.random.default_rng(args.seed)
        self.t0 = time.perf_counter()
        self.results: dict = {
            "study": name,
            "quick": self.quick,
            "seed": args.seed,
            "figures": {},
            "tables": {},
        }
        self.n_throws = 0

    # -- sizes ------------------------------------------------------------------------------
    def res(self, full: int, quick: int) -> int:
        """The main grid size: --res if given, else ``quick`` or ``full``."""
        if self.args.res is not None:
            return int(self.args.res)
        return quick if self.quick else full

    def pick(self, full, quick):
        return quick if self.quick else full

    def log(self, msg: str) -> None:
        print(f"[{self.name} {time.perf_counter() - self.t0:7.1f}s] {msg}", flush=True)

    # -- simulation with cache ----------------------------------------------------------------
    def sample(self, window, res, *, slice_spec="seed", sequences=False, **overrides):
        """:func:`dicetrace.analysis.simulator.sample_window`, cached in OUT/cache."""
        from dicetrace.analysis.simulator import WindowSample, sample_window

        win = window_ranges(window) if isinstance(window, str) else tuple(tuple(w) for w in window)
        res_t = (int(res),) * len(win) if np.isscalar(res) else tuple(int(r) for r in res)
        key = json.dumps([slice_spec, win, res_t, bool(sequences), sorted(overrides.items())], sort_keys=True)
        h = hashlib.sha1(key.encode()).hexdigest()[:16]
        path = self.cache_dir / f"{h}.npz"
        if path.exists() and not self.args.no_cache:
            z = np.load(path, allow_pickle=True)
            return WindowSample(
                labels=z["labels"], t_settle_s=z["t_settle_s"],
                axes=[z[f"axis{i}"] for i in range(len(win))], window=win,
                sequences=z["sequences"] if sequences else None, status_code=z["status_code"],
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

    # -- figures --------------------------------------------------------------------------------
    def save_fig(self, fig, name: str, *, key: str | None = None, caption: str = "") -> str:
        """Save a figure as a small palette PNG (< 300 KB); returns the path relative to OUT."""
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
            out = io.BytesIO()
            pal.save(out, format="PNG", optimize=True)
            if out.tell() <= MAX_FIG_BYTES:
                break
            dpi *= 0.8
        path.write_bytes(out.getvalue())
        plt.close(fig)
        rel = f"figures/{name}.png"
        self.results["figures"][key or name] = {"path": rel, "caption": caption, "bytes": path.stat().st_size}
        return rel

    def add_file(self, rel: str, key: str, caption: str = "") -> None:
        p = self.out / rel
        self.results["figures"][key] = {"path": rel, "caption": caption, "bytes": p.stat().st_size if p.exists() else None}

    # -- results ----------------------------------------------------------------------------------
    def write(self) -> Path:
        self.results["wall_s"] = time.perf_counter() - self.t0
        self.results["n_throws_simulated"] = int(self.n_throws)
        path = self.res_dir / f"{self.name}.json"
        tmp = path.with_suffix(".json.tmp")
        tmp.write_text(json.dumps(jsonable(self.results), indent=1, sort_keys=False))
        os.replace(tmp, path)
        self.log(f"wrote {path} ({self.results['wall_s']:.1f} s)")
        return path

    def write_csv(self, df, name: str) -> str:
        path = self.res_dir / f"{name}.csv"
        df.to_csv(path, index=False)
        return f"results/{name}.csv"
