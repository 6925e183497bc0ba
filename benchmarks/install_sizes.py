"""Disk taken by ``pip install dicetrace`` and by each extra: what the README's install section quotes.

Copies the package's sources (``pyproject.toml``, ``README.md``, ``src/``) to a scratch folder, then for the
base install and for each extra (``explore``, ``jupyter``, ``dask``, ``analysis``, ``all``) creates a new virtual
environment with the ``python3`` running this script and ``pip install``-s the sources with that extra (from
the package index pip is set up for; its cache makes repeats cheap).  Each environment's disk use is measured as
``du`` does (allocated blocks, MiB), with the distributions it holds, and removed.  The GPU extras (``cuda``,
``cuda13``) are not measured: they pull the CUDA libraries for a machine that has a GPU.

Usage: ``python benchmarks/install_sizes.py [--write benchmarks/results/install_sizes.json]``
(a few minutes per environment on a 2-core machine).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import time
import venv
from pathlib import Path

from machine import cpu_model

REPO = Path(__file__).resolve().parents[1]
EXTRAS = ("explore", "jupyter", "dask", "analysis", "all")


def disk_mib(folder: Path) -> float:
    """Allocated size of everything under ``folder`` (as ``du``), MiB; symlinks not followed."""
    total = 0
    for dirpath, dirnames, filenames in os.walk(folder):
        for name in dirnames + filenames:
            st = os.lstat(os.path.join(dirpath, name))
            total += st.st_blocks * 512
    return total / 2**20


def install(src: Path, extra: str | None, where: Path) -> dict:
    """A new environment with the package (and ``extra``) installed: its size, distributions and install time."""
    venv.EnvBuilder(with_pip=True).create(where)
    py = where / "bin" / "python"
    target = str(src) + (f"[{extra}]" if extra else "")
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    t0 = time.perf_counter()
    subprocess.run([str(py), "-m", "pip", "install", "-q", target], check=True, env=env, capture_output=True)
    wall = time.perf_counter() - t0
    dists = subprocess.run([str(py), "-m", "pip", "list", "--format=json"], check=True, env=env,
                           capture_output=True, text=True).stdout
    names = sorted(f"{d['name']}=={d['version']}" for d in json.loads(dists) if d["name"] not in ("pip", "setuptools"))
    return {"extra": extra or "base", "disk_mib": round(disk_mib(where), 1), "distributions": len(names),
            "install_s": round(wall, 1), "installed": names}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--write", type=Path, help="also write the results as JSON here")
    ap.add_argument("--extras", default=",".join(EXTRAS), help="comma-separated extras to measure besides the base")
    args = ap.parse_args()
    rows = []
    with tempfile.TemporaryDirectory(prefix="dicetrace-install-") as tmp:
        src = Path(tmp) / "source"
        src.mkdir()
        for name in ("pyproject.toml", "README.md"):
            shutil.copy2(REPO / name, src / name)
        shutil.copytree(REPO / "src", src / "src", ignore=shutil.ignore_patterns("__pycache__", "*.egg-info"))
        for extra in [None, *filter(None, args.extras.split(","))]:
            where = Path(tmp) / f"venv-{extra or 'base'}"
            row = install(src, extra, where)
            shutil.rmtree(where)
            rows.append(row)
            print(f"{row['extra']:<10} {row['disk_mib']:8.1f} MiB  {row['distributions']:3d} distributions  "
                  f"(installed in {row['install_s']:.0f} s)", flush=True)
    base = rows[0]
    for row in rows[1:]:
        row["adds_mib"] = round(row["disk_mib"] - base["disk_mib"], 1)
        row["adds"] = sorted(set(row["installed"]) - set(base["installed"]))
    result = {
        "what": "disk use of a new virtual environment with dicetrace installed (pip install SRC[EXTRA]), as du",
        "date": time.strftime("%Y-%m-%d"),
        "machine": {"cpu": cpu_model(), "cores": os.cpu_count(), "system": platform.platform(),
                    "python": platform.python_version()},
        "commit": subprocess.run(["git", "rev-parse", "HEAD"], cwd=REPO, capture_output=True, text=True).stdout.strip(),
        "installs": rows,
    }
    if args.write:
        args.write.parent.mkdir(parents=True, exist_ok=True)
        args.write.write_text(json.dumps(result, indent=1) + "\n")
        print(f"wrote {args.write}", file=sys.stderr)


if __name__ == "__main__":
    main()
