"""``dicetrace --version`` and ``--help``: no type-label noise on any flag, the study letters of ``analyze`` explained."""

from __future__ import annotations

import importlib.util
import re

import pytest

import dicetrace
from dicetrace.cli import NOISE_TYPES, app
from dicetrace.studies import INTEGRATOR_TITLES, LETTERS, TITLES, module_name

COMMANDS = ("record", "simulate", "throw", "scan", "accuracy", "stability", "analyze", "explore")


def test_version(dicetrace_cli, tmp_path):
    res = dicetrace_cli("--version", cwd=tmp_path)
    assert res.returncode == 0 and res.stderr == ""
    assert re.fullmatch(rf"dicetrace {re.escape(dicetrace.__version__)} \(numba \S+, numpy \S+, rerun-sdk \S+, "
                        r"pyarrow \S+; Python \S+\)\n", res.stdout), res.stdout


def test_every_command_is_checked():
    import typer.main

    group = typer.main.get_command(app)
    assert sorted(group.list_commands(None)) == sorted(COMMANDS)


@pytest.mark.parametrize("command", [None, *COMMANDS])
def test_help_shows_no_type_noise(dicetrace_cli, tmp_path, monkeypatch, command):
    monkeypatch.setenv("COLUMNS", "200")  # one line per option: each row is checked whole
    res = dicetrace_cli(*([command] if command else []), "--help", cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    rows = [r for r in res.stdout.splitlines() if re.match(r"^│ [ *]*--", r)]
    assert any(re.match(r"^│ [ *]*--help +Show this message and exit", r) for r in rows), res.stdout
    for noise in NOISE_TYPES:
        assert noise not in res.stdout, (command, noise)
    if command is None:
        assert any(re.match(r"^│ [ *]*--version +Print the version", r) for r in rows)
    if command == "scan":  # numbers keep their label: it says what the option takes
        assert any(re.match(r"^│ [ *]*--n +<int> +Number of sample points", r) for r in rows), res.stdout


def test_flags_still_parse_and_text_options_still_name_their_value(dicetrace_cli, tmp_path):
    res = dicetrace_cli("simulate", "--slice", "seed", "--at", "x,y", cwd=tmp_path)
    assert res.returncode == 2 and "--at" in res.stderr and len(res.stderr.strip().splitlines()) == 1
    res = dicetrace_cli("analyze", "--report-only", "--out", str(tmp_path / "none"), cwd=tmp_path)
    assert res.returncode == 2 and "results/" in res.stderr


def test_analyze_help_explains_the_study_letters(dicetrace_cli, tmp_path, monkeypatch):
    monkeypatch.setenv("COLUMNS", "200")
    res = dicetrace_cli("analyze", "--help", cwd=tmp_path)
    assert res.returncode == 0
    for letter, name in LETTERS.items():
        assert re.search(rf"^ +{letter} +{name} +{re.escape(TITLES[name])} *$", res.stdout, re.M), (letter, res.stdout)
    for name, title in INTEGRATOR_TITLES.items():  # every study has this one door, the friction study included
        assert re.search(rf"^ +{name} +{re.escape(title)} *$", res.stdout, re.M), (name, res.stdout)


@pytest.mark.parametrize("alias", ["accuracy", "stability"])
def test_the_old_study_commands_say_they_are_aliases(dicetrace_cli, tmp_path, monkeypatch, alias):
    monkeypatch.setenv("COLUMNS", "200")
    res = dicetrace_cli(alias, "--help", cwd=tmp_path)
    assert res.returncode == 0
    assert f"Alias of `dicetrace analyze {alias}` (the same options)" in res.stdout


@pytest.mark.parametrize("name", sorted(TITLES) + sorted(INTEGRATOR_TITLES))
def test_each_title_is_its_modules_own(name):
    """The titles shown by analyze --help are the first docstring lines of the study modules (read, not imported)."""
    spec = importlib.util.find_spec(module_name(name))
    with open(spec.origin, encoding="utf-8") as f:
        first = f.readline()
    if name in TITLES:
        letter = {n: k for k, n in LETTERS.items()}[name]
        assert first.rstrip().rstrip(".") == f'"""Study {letter} ({name}): {TITLES[name]}'
    else:
        assert first.rstrip().rstrip(".") == f'"""Study {name}: {INTEGRATOR_TITLES[name]}'


@pytest.mark.parametrize("command", COMMANDS)
def test_help_shows_every_bracket_of_the_help_texts(dicetrace_cli, tmp_path, monkeypatch, command):
    """Rich reads ``[word]`` in a help text as markup and drops it: ``analyze --help`` said ``pip install
    'dicetrace'`` for ``'dicetrace[cuda]'``, ``record --help`` lost ``[default: seed]``.  Every bracketed part of
    every option's help text is shown as written (escaped ``\\[`` in the source where it would read as markup)."""
    import typer.main

    monkeypatch.setenv("COLUMNS", "2000")  # one line per option: nothing wrapped
    res = dicetrace_cli(command, "--help", cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    shown = " ".join(res.stdout.split())
    params = typer.main.get_command(app).commands[command].params
    brackets = [m.group(0).lstrip("\\") for p in params for m in re.finditer(r"\\?\[[^\[\]]*\]", p.help or "")]
    assert all(b in shown for b in brackets), [b for b in brackets if b not in shown]
    if command == "analyze":
        assert "pip install 'dicetrace[cuda]'" in shown
