"""``simulate``'s table: every row as fixed-width text (rich's layout, without its cost); a terminal gets a short one."""

from __future__ import annotations

import io
import math
import sys
import time

import numpy as np
import pytest

from dicetrace.commands import simulate as cmd

NAMES = ["ic_id", "x", "y", "vx", "vy", "vz", "Lx", "Ly", "Lz", "outcome", "steps", "t_settle_s", "status",
         "contact_sequence"]  # fmt: skip


def _rows(n: int, seed: int = 0) -> list[list]:
    rng = np.random.default_rng(seed)
    statuses = ["settled", "time_cap", "blow_up"]
    rows = []
    for i in range(n):
        floats = [float(v) for v in rng.normal(0, 10.0 ** rng.integers(-3, 4), 8)]
        if i == 3:
            floats[0] = math.nan
        outcome = int(rng.integers(-1, 7))
        seq = "-".join(str(int(v)) for v in rng.integers(0, 9, int(rng.integers(1, 30))))
        rows.append([i, *floats, outcome, int(rng.integers(1, 60000)), float(rng.uniform(0, 60)),
                     statuses[i % 3], seq])
    return rows


def _rich_table(names, rows) -> str:
    """The table as rich drew it for a file or pipe before (box-less, width 100000, trailing spaces stripped)."""
    from rich.console import Console
    from rich.table import Table

    table = Table(box=None, header_style="bold", pad_edge=False)
    for n in names:
        table.add_column(n, justify="right" if n in cmd._NUMERIC else "left", overflow="fold")
    for r in rows:
        table.add_row(*[cmd.fmt_num(v) if isinstance(v, float) else str(v) for v in r])
    buf = io.StringIO()
    Console(file=buf, width=100000, no_color=True, highlight=False, soft_wrap=False).print(table)
    return "\n".join(line.rstrip() for line in buf.getvalue().splitlines()) + "\n"


@pytest.mark.parametrize("n", [0, 1, 7, 200])
def test_the_plain_table_is_rich_s_layout_character_for_character(n):
    rows = _rows(n, seed=n)
    assert cmd.plain_table(NAMES, rows) == _rich_table(NAMES, rows)


@pytest.mark.slow  # about 0.7 s
def test_ten_thousand_rows_take_well_under_a_second():
    rows = _rows(10_000)
    t0 = time.perf_counter()
    text = cmd.plain_table(NAMES, rows)
    elapsed = time.perf_counter() - t0
    assert text.count("\n") == 10_001
    assert elapsed < 1.5, f"{elapsed:.2f} s for 10,000 rows (rich's table took ~8 s)"


class _Tty(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_a_terminal_gets_every_row_up_to_the_limit(monkeypatch):
    rows = _rows(cmd.TTY_ROWS)
    out = _Tty()
    monkeypatch.setattr(sys, "stdout", out)
    monkeypatch.setenv("COLUMNS", "400")  # a wide terminal: one line per row
    cmd.emit(NAMES, rows, "table", None, meta={})
    text = out.getvalue()
    assert "more rows" not in text
    ids = [int(line.split()[0]) for line in text.splitlines() if line.split() and line.split()[0].isdigit()]
    assert ids == list(range(cmd.TTY_ROWS))


def test_a_terminal_gets_the_first_rows_the_count_the_outcomes_and_the_hint(monkeypatch):
    rows = _rows(5000)
    out = _Tty()
    monkeypatch.setattr(sys, "stdout", out)
    monkeypatch.setenv("COLUMNS", "400")  # a wide terminal: one line per row
    t0 = time.perf_counter()
    cmd.emit(NAMES, rows, "table", None, meta={})
    assert time.perf_counter() - t0 < 3
    text = out.getvalue()
    ids = [int(line.split()[0]) for line in text.splitlines() if line.split() and line.split()[0].isdigit()]
    assert ids[: cmd.TTY_HEAD] == list(range(cmd.TTY_HEAD))
    assert f"… and {5000 - cmd.TTY_HEAD:,} more rows (outcomes of all 5,000: " in text
    n1 = sum(r[9] == 1 for r in rows)
    assert f"face 1: {100 * n1 / 5000:.1f}%" in text and "not settled:" in text and "undefined:" in text
    assert "--format csv" in text and "--out FILE" in text


@pytest.mark.slow  # about 0.7 s
def test_a_file_or_pipe_gets_every_row(tmp_path):
    rows = _rows(500)
    cmd.emit(NAMES, rows, "table", tmp_path / "t.txt", meta={})
    assert (tmp_path / "t.txt").read_text() == _rich_table(NAMES, rows)


def test_the_readme_states_the_terminal_limits():
    from pathlib import Path

    readme = " ".join((Path(__file__).resolve().parents[2] / "README.md").read_text().split())
    assert f"a table of more than {cmd.TTY_ROWS} rows shows the first {cmd.TTY_HEAD}" in readme
