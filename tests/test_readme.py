"""The README as a user meets it: its Python blocks run as written, and its first command works in a clone.

Python blocks: each ```python block runs, as written, in one fresh namespace
with a temporary folder as the current directory.  A line followed by a
comment line ``# <value>`` states what the line evaluates to: the test
evaluates it and compares its ``repr`` with the comment.

First command: ``git clone`` of this repository (its committed HEAD) into a
temporary folder, then the README's first command run there by ``bash``,
checking that the ``.rrd`` it names is written and that the clone's ``git
status`` stays clean.  The command begins by creating ``.venv`` and
``pip install``-ing the package into it, which downloads and installs every
dependency (minutes, and a package index); by default the clone's ``.venv``
is the environment running the tests (a link) and the install step is
skipped, so what runs verbatim is the record itself, with the clone's
sources first on the path.  ``DICETRACE_INSTALL_TEST=1`` runs the whole
command as written, install included.
"""

from __future__ import annotations

import ast
import os
import re
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
README = (REPO / "README.md").read_text()


def _blocks(lang: str) -> list[str]:
    return re.findall(rf"^```{lang}\n(.*?)^```", README, flags=re.S | re.M)


def _claims(block: str) -> list[tuple[str, str]]:
    """(expression, stated repr) for every line followed by a ``# <value>`` comment line."""
    lines = block.splitlines()
    out = []
    for line, nxt in zip(lines, lines[1:]):
        code = line.split("  #")[0].strip()
        if nxt.startswith("# ") and code and not code.startswith("#"):
            try:
                ast.literal_eval(nxt[2:].strip())
            except (ValueError, SyntaxError):
                continue  # a prose comment, not a stated value
            out.append((code, nxt[2:].strip()))
    return out


def test_the_readme_has_python_blocks_that_state_values():
    blocks = _blocks("python")
    assert blocks and any(_claims(b) for b in blocks)


@pytest.mark.parametrize("index", range(len(_blocks("python"))))
def test_python_block_runs_as_written_and_its_stated_values_hold(index, tmp_path, monkeypatch):
    block = _blocks("python")[index]
    monkeypatch.chdir(tmp_path)
    namespace: dict = {"__name__": "__readme__"}
    exec(compile(block, f"README.md python block {index + 1}", "exec"), namespace)
    for expr, stated in _claims(block):
        got = eval(expr, namespace)
        assert repr(got) == stated, f"README says {expr} is {stated}, it is {got!r}"


def _first_command() -> str:
    first = _blocks("bash")[0]
    return next(line for line in first.splitlines() if line.strip() and not line.lstrip().startswith("#"))


@pytest.mark.slow
def test_the_first_command_records_a_roll_in_a_fresh_clone(tmp_path):
    if shutil.which("git") is None or not (REPO / ".git").exists():
        pytest.skip("needs git and this repository's history")
    clone = tmp_path / "clone"
    subprocess.run(["git", "clone", "-q", str(REPO), str(clone)], check=True, timeout=120)
    command = _first_command()
    parts = [p.strip() for p in command.split("&&")]
    assert parts[0].startswith("python3 -m venv .venv") and "pip install" in parts[1], command
    env = {k: v for k, v in os.environ.items() if k not in ("VIRTUAL_ENV",)}
    if os.environ.get("DICETRACE_INSTALL_TEST") == "1":
        run = command
        env.pop("PYTHONPATH", None)
    else:  # the running environment stands in for the install (see the module docstring)
        (clone / ".venv").symlink_to(Path(sys.prefix), target_is_directory=True)
        run = " && ".join(parts[2:])
        env["PYTHONPATH"] = str(clone / "src")
    proc = subprocess.run(["bash", "-c", run], cwd=clone, env=env, capture_output=True, text=True, timeout=1800)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    named = re.search(r"(recordings/\S+\.rrd)", README.split("\n```", 2)[0] + _blocks("bash")[0])
    rrd = clone / named.group(1)
    assert rrd.stat().st_size > 10_000 and rrd.read_bytes()[:4] == b"RRF2"
    assert str(rrd.relative_to(clone)) in proc.stdout + proc.stderr  # it says where it wrote
    if os.environ.get("DICETRACE_INSTALL_TEST") != "1":
        (clone / ".venv").unlink()
    status = subprocess.run(["git", "status", "--porcelain"], cwd=clone, capture_output=True, text=True, check=True)
    assert status.stdout == "", status.stdout  # outputs are ignored, nothing tracked changed
    assert shlex.split(parts[-1])[0] == ".venv/bin/dicetrace"


def _slug(heading: str) -> str:
    """GitHub's anchor of a heading: lower case, punctuation dropped, spaces to hyphens."""
    return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")


def test_the_first_screen_says_what_it_is_shows_it_gives_the_commands_and_the_contents():
    head, first_block, rest = README.split("\n```", 2)
    assert head.startswith("# dicetrace\n\n**dicetrace** is ") and len(head.splitlines()) <= 10
    assert "](docs/first-screen.png)" in head and (REPO / "docs" / "first-screen.png").exists()
    assert first_block.startswith("bash\n") and "bash .ci/run" in first_block
    contents = rest[rest.index("**Contents:**"):].split("\n\n", 1)[0]
    assert rest.index("**Contents:**") < 10 and rest.index("**Contents:**") < rest.index("\n## ")
    headings = {_slug(h) for h in re.findall(r"^## (.+)$", README, re.M)}
    links = re.findall(r"\]\(([^)]+)\)", contents)
    assert len(links) >= 12
    for link in links:
        if link.startswith("#"):
            assert link[1:] in headings, link
        else:
            assert (REPO / link).exists(), link
    assert {f"#{h}" for h in headings} <= set(links)  # every section is listed
    for internal in ("scripts/test.sh", "Xvfb", "compile_kernels"):  # the CI's internals live in CONTRIBUTING.md
        assert internal not in README.split("\n## ", 1)[0], internal


def test_the_first_picture_is_the_committed_map_beside_the_committed_viewer_shot():
    """docs/first-screen.png is what scripts/first_screen.py makes of docs/red-sea.png and docs/viewer.png (run it
    again when either changes)."""
    import importlib.util

    import numpy as np
    from PIL import Image

    spec = importlib.util.spec_from_file_location("first_screen", REPO / "scripts" / "first_screen.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    made = np.asarray(mod.compose())
    with Image.open(REPO / "docs" / "first-screen.png") as im:
        committed = np.asarray(im.convert("RGB"))
    assert made.shape == committed.shape and np.array_equal(made, committed)


def test_the_numbers_of_contributing_md_are_held_by_results_files():
    import importlib.util

    spec = importlib.util.spec_from_file_location("report_figures", REPO / "tests" / "studies" / "test_report_figures.py")
    rf = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(rf)
    values = rf.held_values()
    found = rf.figures((REPO / "CONTRIBUTING.md").read_text())
    assert {"547.6", "237.0", "241.01", "708.9"} <= {f for f, _ in found}
    unheld = [(f, line) for f, line in found if f not in rf.EXCEPTIONS and not rf.is_held(f, values)]
    assert not unheld, unheld
