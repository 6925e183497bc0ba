"""``dicetrace throw``: many hand throws of any die, their face counts with intervals, and the rows as Parquet.

Examples::

    dicetrace throw --n 100000                          # the cube, casual hand throws: is it fair?
    dicetrace throw --die 2,2,3 --n 100000              # a box 3 cm tall
    dicetrace throw --load 0.3@-0.9,0,0 --throw vigorous --n 20000 --out out/loaded

Each throw starts from its own pose, drawn by :class:`dicetrace.throws.HandThrow`
(``--throw casual|gentle|vigorous``, seeded by ``--seed``), and runs on the
continuous contact integrators (``--preset physical`` by default).  The throws run
in chunks with a progress bar on standard error; the rows (IC, pose, outcome,
contact sequence) go to ``OUT/rolls.parquet`` (default ``out/throws``), written
under a temporary name and renamed when complete, so an interrupted run leaves
nothing half-written.  Standard output gets the face table: count, share and its
95 % Wilson interval per face, the throws that ended on an edge or at the time cap,
and for a die that is a uniform cube the χ² test of fairness.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path
from typing import Optional

import typer

from dicetrace.commands import options as opts
from dicetrace.commands._common import fail, output_dir

#: Throws per call of the batch (one progress step).
CHUNK = 2000
#: The largest --n: rows are streamed to disk, but the counts and the chunk sizes are plain integers.
MAX_N = 10**8


def face_table(outcome, cube: bool) -> tuple[str, dict]:
    """The face table of ``outcome`` (one line per face, then what did not end on a face) and its numbers."""
    from scipy import stats

    from dicetrace.analysis.fairness import face_counts

    counts = face_counts(outcome)
    faces, lo, hi = counts["faces"], counts["ci_low"], counts["ci_high"]
    n = sum(faces)
    lines = ["face  throws      share   95 % interval"]
    for f in range(6):
        share = faces[f] / n if n else float("nan")
        lines.append(f"{f + 1:>4}  {faces[f]:>6}  {share:9.4f}   {lo[f]:.4f}-{hi[f]:.4f}")
    edge, unsettled = counts["edge"], counts["unsettled"]
    lines.append(f"on a face {n}, on an edge {edge}, at the time cap {unsettled}")
    out = {"faces": faces, "on_face": n, "edge": edge, "unsettled": unsettled}
    if cube and n:
        p = float(stats.chisquare(faces).pvalue)
        out["fair_chi2_p"] = p
        lines.append(f"a fair die? chi-square test of equal shares: p = {p:.3g}")
    return "\n".join(lines), out


def register(app: typer.Typer) -> None:
    @app.command("throw")
    def throw_cmd(
        n: int = typer.Option(10000, "--n", help=f"Throws (1 to {MAX_N:,})."),
        die: opts.DieOption = None,
        load: opts.LoadOption = None,
        throw: str = typer.Option("casual", "--throw", help="How the hand throws (dicetrace.throws): casual (released "
                                  "8-20 cm up, 0.3-1.2 m/s across, 5-30 rad/s of spin), gentle or vigorous; the "
                                  "orientation is uniformly random."),
        seed: int = typer.Option(0, "--seed", help="Seed of the throws (the same seed, the same throws)."),
        preset: str = typer.Option("physical", "--preset", help="The model (a box or loaded die needs a continuous "
                                   "contact integrator: physical's contact-tsit5, or --integrator contact-dop853)."),
        integrator: opts.IntegratorOption = None,
        tol: opts.TolOption = None,
        out: Path = typer.Option(Path("out/throws"), "--out", help="Folder for rolls.parquet (one row a throw: IC, "
                                 "pose qx, qy, qz, qw, z0_cm, outcome, contact sequence)."),
        threads: Optional[int] = typer.Option(None, "--threads", help="numba threads (default: all)."),
        quiet: bool = typer.Option(False, "--quiet", "-q", help="No progress bar."),
    ) -> None:
        """Throw any die many times as a hand throws it: the face shares with 95 % intervals, and the rows as Parquet.

        Exit code 1 when a throw ends in a numerical failure (its row says so), 2 on bad input.
        """
        from dicetrace.throws import THROWS

        if not 1 <= n <= MAX_N:
            fail(f"--n must be a whole number in [1, {MAX_N:,}], got {n}")
        if throw not in THROWS:
            fail(f"--throw must be one of {', '.join(THROWS)}, got {throw!r}")
        if not 0 <= seed < 2**63:
            fail(f"--seed must be an integer in [0, 2**63), got {seed}")
        if threads is not None and threads < 1:
            fail(f"--threads must be >= 1, got {threads}")
        cfg = opts.build_config(preset, integrator, None, None, tol=tol, overrides=opts.body_overrides(die, load))
        folder = output_dir(out, "--out")
        run_throws(cfg, THROWS[throw], n, seed, folder, threads=threads, quiet=quiet)


def run_throws(cfg, hand, n: int, seed: int, folder: Path, *, threads=None, quiet: bool = False) -> dict:
    """``n`` throws of ``hand`` with ``cfg``, chunk by chunk into ``folder/rolls.parquet``; prints the face table."""
    import numpy as np
    import pyarrow.parquet as pq
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

    import json
    from dataclasses import asdict

    from dicetrace.simulate import simulate_batch
    from dicetrace.sinks._common import OutputError, Staging
    from dicetrace.status import Status
    from dicetrace.tables import METADATA_KEY, metadata_json

    throws = hand.sample(n, cfg, seed)  # all poses at once: 88 bytes a throw
    outcome = np.empty(n, dtype=np.int8)
    failed = 0
    t0 = time.perf_counter()
    dest = folder / "rolls.parquet"
    try:
        with Staging() as staging:
            tmp = staging.path(dest)
            writer = None
            try:
                with Progress(TextColumn("throwing"), BarColumn(), MofNCompleteColumn(), TimeRemainingColumn(),
                              disable=quiet or not sys.stderr.isatty(), transient=True) as bar:
                    task = bar.add_task("throws", total=n)
                    for a in range(0, n, CHUNK):
                        b = min(n, a + CHUNK)
                        r = simulate_batch(throws.ics[a:b], config=cfg, orientations=throws.orientations[a:b],
                                           heights_cm=throws.heights_cm[a:b], threads=threads)
                        outcome[a:b] = r.outcome
                        failed += int(np.sum((r.status_code == Status.NON_FINITE) | (r.status_code == Status.BLOW_UP)))
                        table = r.to_arrow(ic_ids=np.arange(a, b))
                        if writer is None:  # the file's metadata: the configuration, every throw's count, the hand
                            meta = metadata_json(cfg, throws.ics, extra={"device": r.device, "throw": {
                                "model": hand.name, "seed": seed, "n": n, **asdict(hand)}})
                            schema = table.schema.with_metadata({METADATA_KEY: json.dumps(meta, sort_keys=True)})
                            writer = pq.ParquetWriter(tmp, schema)
                        writer.write_table(table.replace_schema_metadata(schema.metadata))
                        bar.advance(task, b - a)
            finally:
                if writer is not None:
                    writer.close()
            staging.commit()
    except OutputError as e:
        fail(str(e))
    wall = time.perf_counter() - t0
    text, numbers = face_table(outcome, cfg.preset.is_cube)
    print(text)
    print(f"{n} throws ({hand.name}, seed {seed}) in {wall:.1f} s: {n / wall:,.0f} throws/s; wrote {dest}")
    if failed:
        print(f"dicetrace: {failed} throws ended in a numerical failure (status non_finite or blow_up in {dest})",
              file=sys.stderr)
        raise typer.Exit(1)
    return numbers
