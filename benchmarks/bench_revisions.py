"""The cost per throw of two revisions of dicetrace, measured in one run: before and after a change to the kernels.

Checks each revision out into a temporary git worktree (``--after`` defaults to the working tree itself), loads or
compiles its kernels outside the timing (each revision's kernels are cached under their own digest), then times
the same batch of throws on one thread in each, alternating between the two revisions ``--rounds`` times; every
timed run is a fresh interpreter that keeps the best process CPU time of ``--repeat`` batches.  It prints, per
preset, each revision's best and worst ms per throw, the ratio of the bests (after / before), the steps in all,
and on how many throws the two revisions give the same outcome and the same step count (a change of rounding
moves the steps of a chaotic throw; a change of the physics moves its face too).

The throws are the seed slice (``seed_slice``, x, y uniform in [0, 20]², rng ``--seed``): the program's
throws for ``seed``, their L mirrored for ``physical`` (``make_config``'s convention).

Usage::

    python benchmarks/bench_revisions.py --before acaf0e8 [--after HEAD] [--presets physical,seed]
        [--n 200] [--n-seed 20000] [--rounds 3] [--repeat 3] [--write benchmarks/results/NAME.json]

Keep the machine otherwise quiet: the ratio holds on a noisy machine only as far as the rounds agree.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from machine import cpu_model  # noqa: E402

REPO = Path(__file__).resolve().parents[1]

#: One timed run in a fresh interpreter: argv = preset, n, seed, repeat; prints JSON.
_RUN = """
import json, sys, time
import numpy as np
from dicetrace.ics import seed_slice
from dicetrace.simulate import simulate_batch
preset, n, seed, repeat = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4])
rng = np.random.default_rng(seed)
ics = seed_slice(rng.uniform(0, 20, n), rng.uniform(0, 20, n))
simulate_batch(ics[:2], config=preset, threads=1)  # load (or compile) outside the timing
best = float("inf")
for _ in range(repeat):
    t0 = time.process_time()
    r = simulate_batch(ics, config=preset, threads=1)
    best = min(best, time.process_time() - t0)
print(json.dumps(dict(s=best, steps=r.steps.tolist(), outcome=r.outcome.tolist())))
"""


def _git(*args: str) -> str:
    return subprocess.run(["git", "-C", str(REPO), *args], check=True, capture_output=True, text=True).stdout.strip()


def _run(src: Path, preset: str, n: int, seed: int, repeat: int) -> dict:
    env = {**os.environ, "PYTHONPATH": str(src), "NUMBA_NUM_THREADS": "1"}
    res = subprocess.run([sys.executable, "-c", _RUN, preset, str(n), str(seed), str(repeat)], capture_output=True,
                         text=True, env=env, cwd=src.parent)
    if res.returncode != 0:
        raise SystemExit(f"bench_revisions: a run of {src.parent} failed: {res.stderr.strip().splitlines()[-1]}")
    return json.loads(res.stdout.strip().splitlines()[-1])


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--before", required=True, help="the revision before the change (a commit, a tag, HEAD~1)")
    ap.add_argument("--after", default=None, help="the revision after it (default: the working tree as it is)")
    ap.add_argument("--presets", default="physical,seed", help="comma-separated presets (default physical,seed)")
    ap.add_argument("--n", type=int, default=200, help="throws a batch (default 200)")
    ap.add_argument("--n-seed", type=int, default=20000,
                    help="throws a batch of the seed preset, whose throws are ~15x cheaper (default 20000)")
    ap.add_argument("--seed", type=int, default=3, help="rng seed of the throws (default 3)")
    ap.add_argument("--rounds", type=int, default=3, help="alternations of the two revisions (default 3)")
    ap.add_argument("--repeat", type=int, default=3, help="batches a run, the best kept (default 3)")
    ap.add_argument("--write", type=Path, default=None, help="also write the figures to this JSON file")
    args = ap.parse_args(argv)
    presets = [p.strip() for p in args.presets.split(",") if p.strip()]
    with tempfile.TemporaryDirectory(prefix="bench_revisions_") as tmp:
        trees = {}
        for name, rev in (("before", args.before), ("after", args.after)):
            if rev is None:
                trees[name] = (REPO / "src", f"working tree at {_git('rev-parse', '--short', 'HEAD')}"
                               + (" (changed)" if _git("status", "--porcelain", "--untracked-files=no") else ""))
                continue
            path = Path(tmp) / name
            _git("worktree", "add", "--detach", "--quiet", str(path), rev)
            trees[name] = (path / "src", _git("rev-parse", "--short", rev))
        try:
            figures = _measure(trees, presets, args)
        finally:
            for name, rev in (("before", args.before), ("after", args.after)):
                if rev is not None:
                    _git("worktree", "remove", "--force", str(Path(tmp) / name))
    out = dict(before=trees["before"][1], after=trees["after"][1], seed=args.seed, rounds=args.rounds,
               repeat=args.repeat, threads=1, cpu=cpu_model(), cpu_count=os.cpu_count(), machine=platform.machine(),
               python=platform.python_version(), finished=time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime()),
               presets=figures)
    if args.write:
        args.write.parent.mkdir(parents=True, exist_ok=True)
        args.write.write_text(json.dumps(out, indent=1) + "\n")
        print(f"wrote {args.write}")


def _measure(trees: dict, presets: list[str], args) -> dict:
    figures = {}
    for preset in presets:
        n = args.n_seed if preset == "seed" else args.n
        for name, (src, _) in trees.items():  # compile or load each revision's kernels, untimed
            _run(src, preset, 2, args.seed, 1)
        runs = {name: [] for name in trees}
        for _ in range(args.rounds):
            for name, (src, _) in trees.items():
                runs[name].append(_run(src, preset, n, args.seed, args.repeat))
        ms = {name: [1e3 * r["s"] / n for r in rs] for name, rs in runs.items()}
        b, a = runs["before"][-1], runs["after"][-1]
        same_steps = float(np.mean(np.equal(b["steps"], a["steps"])))
        same_outcome = float(np.mean(np.equal(b["outcome"], a["outcome"])))
        ratio = min(ms["after"]) / min(ms["before"])
        figures[preset] = dict(n=n, ms_per_throw=ms, ratio_of_bests=ratio,
                               steps_total={k: int(sum(r[-1]["steps"])) for k, r in runs.items()},
                               same_steps=same_steps, same_outcome=same_outcome)
        for name in trees:
            print(f"{preset:9s} {name:6s} {trees[name][1]:>24s}: {min(ms[name]):.4f}–{max(ms[name]):.4f} ms a throw, "
                  f"{figures[preset]['steps_total'][name]:,} steps in all")
        print(f"{preset:9s} after / before, best runs: {ratio:.3f}; same steps {same_steps:.3f}, "
              f"same outcome {same_outcome:.3f} ({n} throws, one thread)", flush=True)
    return figures


if __name__ == "__main__":
    main()
