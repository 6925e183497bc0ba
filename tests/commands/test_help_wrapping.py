"""``--help`` wraps cleanly at any terminal width: no word cut in two, no short line whose successor's first word
would have fitted on it, no fragment of a table row falling back to the left margin.

Every command's help is printed at 60, 80, 120 and 200 columns (in-process, ``COLUMNS`` set as a terminal
would) and read back line by line: the description's prose paragraphs and table rows (outside the boxes)
and the help column of the option and argument boxes.
"""

from __future__ import annotations

import re

import pytest

from dicetrace.cli import reflow

COMMANDS = (None, "record", "simulate", "scan", "accuracy", "stability", "analyze", "explore")
WIDTHS = (60, 80, 120, 200)
BOX = "│╭╮╰╯─"
#: What typer sets after an option's help as items of their own (a line of their own where the help wrapped).
TYPER_ITEMS = ("[default:", "[required]", "[env var:")


def _indent(line: str) -> int:
    return len(line) - len(line.lstrip())


def _fits(prev: str, nxt: str, room: int) -> bool:
    """Whether ``nxt``'s first word would have fitted at the end of ``prev`` within ``room`` columns."""
    return len(prev.rstrip()) + 1 + len(nxt.split()[0]) <= room


def description_problems(lines: list[str], width: int) -> list[str]:
    """Ragged breaks and stray fragments in the text outside the boxes (the usage line aside)."""
    text = [ln for ln in lines if not ln.lstrip().startswith(tuple(BOX))]
    paragraphs, cur = [], []
    for ln in text:
        if ln.strip():
            cur.append(ln.rstrip())
        elif cur:
            paragraphs.append(cur)
            cur = []
    if cur:
        paragraphs.append(cur)
    out = []
    for para in paragraphs:
        if para[0].lstrip().startswith("Usage:"):
            continue
        row = _indent(para[0])  # 1: prose (typer's padding); more: the rows of a table
        for prev, ln in zip(para, para[1:]):
            if _indent(ln) < row or (row == 1 and _indent(ln) != 1):
                out.append(f"fragment out of line: {ln!r} after {prev!r}")
            elif (_indent(ln) == row == 1 or _indent(ln) > row) and _fits(prev, ln, width - 1):
                out.append(f"ragged: {ln.split()[0]!r} would fit after {prev!r}")
    return out


def box_problems(lines: list[str]) -> list[str]:
    """Ragged breaks in the help column of each box (option and argument panels)."""
    out, panel = [], []
    for ln in lines + [""]:
        if ln.startswith("│") and ln.rstrip().endswith("│"):
            panel.append(ln.rstrip()[1:-1])
            continue
        if panel:
            starts = [_indent(c) for c in panel if c.strip() and _indent(c) > 8]
            if starts:
                col = max(set(starts), key=starts.count)  # the help column: where continuation lines begin
                room = len(panel[0]) - col - 1  # the cell's width (one column of padding on the right)
                for prev, c in zip(panel, panel[1:]):
                    cont = c[:col].strip() == "" and c[col:].strip() and not c[col:].startswith(TYPER_ITEMS)
                    has_help = prev[col - 1:col] == " " and prev[col:].strip()
                    if cont and has_help and _fits(prev[col:], c[col:].lstrip(), room):
                        out.append(f"ragged cell: {c.split()[0]!r} would fit after {prev[col:].rstrip()!r}")
            panel = []
    return out


def _tokens(text: str) -> set[str]:
    return set(re.sub(f"[{BOX}]", " ", text).split())


def _help(dicetrace_cli, tmp_path, monkeypatch, command, width) -> str:
    monkeypatch.setenv("COLUMNS", str(width))
    res = dicetrace_cli(*([command] if command else []), "--help", cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    return res.stdout


@pytest.mark.parametrize("command", COMMANDS)
def test_help_wraps_cleanly_at_every_width(dicetrace_cli, tmp_path, monkeypatch, command):
    wide = _tokens(_help(dicetrace_cli, tmp_path, monkeypatch, command, 1000))
    for width in WIDTHS:
        text = _help(dicetrace_cli, tmp_path, monkeypatch, command, width)
        lines = text.splitlines()
        assert max(map(len, lines)) <= width, (command, width)
        cut = _tokens(text) - wide  # a word cut in two (or shortened with an ellipsis) is a new token
        assert not cut, (command, width, sorted(cut)[:10])
        problems = description_problems(lines, width) + box_problems(lines)
        assert not problems, (command, width, problems[:5], text)


RAGGED = """\
 Usage: dicetrace thing [OPTIONS]

 The first paragraph.

 Open a file with `rerun FILE.rrd`.  Sinks (as in rerun's
 example scripts): --out/--save FILE
 (the default when no other sink is given).

   a  cells       the cell structure of the home window
 (writeup 4.1)
"""


def test_the_checks_see_the_old_ragged_help():
    problems = description_problems(RAGGED.splitlines(), 60)
    assert any("ragged: '(the'" in p for p in problems), problems
    assert any("fragment out of line: ' (writeup 4.1)'" in p for p in problems), problems
    box = ["╭─ Options ──────────────────────╮",
           "│ --ic      One IC:              │",
           "│           (cm/s).              │",
           "╰────────────────────────────────╯"]
    assert box_problems(box) and not box_problems([box[0], "│ --ic      One IC: VX,VY,VZ,LX │",
                                                   "│           (cm/s) and more.     │", box[3]])


def test_reflow_joins_prose_and_hangs_table_rows():
    text = "Title\nline.\n\nOne two\nthree four five.\n\n  a  name   first second third fourth\n  b  other  x"
    got = reflow(text, 24)
    assert got == ("Title line.\n\nOne two three four five.\n\n"
                   "  a  name   first second\n"
                   "            third fourth\n"
                   "  b  other  x")
    assert reflow("T\n\n--a-long-option-name --b", 10) == "T\n\n--a-long-option-name\n--b"  # no word is cut


@pytest.mark.parametrize("args", [["accuracy"], ["stability"], ["analyze", "accuracy"]])
def test_the_integrator_studies_still_take_integrators_but_list_only_integrator(dicetrace_cli, tmp_path, monkeypatch,
                                                                                args):
    res = dicetrace_cli(*args, "--integrators", "nonsense", "--quick", "--out", str(tmp_path / "o"), cwd=tmp_path)
    assert res.returncode == 2 and res.stderr.startswith("dicetrace: error: --integrator: unknown integrator nonsense")
    assert "--integrators" not in _help(dicetrace_cli, tmp_path, monkeypatch, args[0], 200)
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("command", COMMANDS[1:])
def test_help_shows_every_word_of_the_description(dicetrace_cli, tmp_path, monkeypatch, command):
    """Nothing of a description is lost to rich's markup (``[analysis]`` in a help text is a style tag, not text)."""
    import typer.main

    from dicetrace.cli import app

    described = typer.main.get_command(app).commands[command].help.split()
    shown = _tokens(_help(dicetrace_cli, tmp_path, monkeypatch, command, 1000))
    assert [w for w in described if w not in shown] == []
