"""Every file or folder the README's commands write lands where ``git status`` does not see it.

A user who follows the README in a clone must not end up with untracked files: each output path that
a README command names (``--out``, ``--save``, ``--parquet``, ``--png``, ``--rrd``) is git-ignored, or is
a committed figure that the command regenerates on purpose (a tracked file such as ``docs/red-sea.png``).
"""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
README = (REPO / "README.md").read_text()
OPTIONS = ("--out", "--save", "--parquet", "--png", "--rrd")


def _commands() -> list[str]:
    """The README's code: every line of its code blocks and every inline code span, comments cut."""
    blocks = re.findall(r"^```\w*\n(.*?)^```", README, flags=re.S | re.M)
    lines = [ln for b in blocks for ln in b.splitlines()]
    prose = re.sub(r"^```\w*\n.*?^```", "", README, flags=re.S | re.M)
    lines += re.findall(r"`([^`\n]+)`", prose)
    return [ln.split("#")[0] for ln in lines]


def _outputs() -> list[str]:
    pat = re.compile(r"(?:%s)[ =](\S+)" % "|".join(re.escape(o) for o in OPTIONS))
    found = {m.group(1).strip("`'\"") for cmd in _commands() for m in pat.finditer(cmd)}
    return sorted(p for p in found if p not in ("-", "FILE", "DIR", "OUT") and not p.startswith(("$", "/", "<")))


def test_the_readme_names_output_paths():
    outs = _outputs()
    assert {"out/", "scans/red-sea"} <= set(outs), outs


@pytest.mark.skipif(shutil.which("git") is None or not (REPO / ".git").exists(), reason="needs a git checkout")
@pytest.mark.parametrize("path", _outputs())
def test_every_output_path_the_readme_names_is_ignored_or_a_committed_figure(path):
    ignored = subprocess.run(["git", "check-ignore", "-q", "--no-index", path], cwd=REPO).returncode == 0
    tracked = subprocess.run(["git", "ls-files", "--error-unmatch", path], cwd=REPO,
                             capture_output=True).returncode == 0
    assert ignored or tracked, f"{path}: a README command writes it, and git status would show it"
