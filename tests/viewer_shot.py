"""The real Rerun viewer's screenshot of a recording, headless under Xvfb (shared by the viewer tests)."""

from __future__ import annotations

import os
import shutil
import socket
import subprocess
import sys
from pathlib import Path

RERUN_CLI = Path(sys.executable).parent / "rerun"
XVFB = shutil.which("xvfb-run")
RERUN = str(RERUN_CLI) if RERUN_CLI.exists() else shutil.which("rerun")


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def screenshot(rrd: Path, folder: Path) -> Path:
    """The viewer's screenshot of ``rrd`` in a 1400x900 window under Xvfb (``folder/shot.png``).

    Each viewer gets a port of its own: with one port, a second screenshot at the same time
    (pytest -n 2) hands its recording to the first viewer, and ``--new`` (pick a free port)
    races when two viewers start together ("Address already in use").  A port taken in the
    instant between picking and binding is retried once.
    """
    png = folder / "shot.png"
    env = {**os.environ, "XDG_RUNTIME_DIR": str(folder)}
    for attempt in range(2):
        cmd = [XVFB, "-a", "-s", "-screen 0 1400x900x24", RERUN, str(rrd), "--port", str(_free_port()),
               "--screenshot-to", str(png), "--window-size", "1400x900"]
        res = subprocess.run(cmd, capture_output=True, text=True, timeout=120, env=env, cwd=folder)
        if res.returncode == 0 or "Address already in use" not in res.stderr:
            break
    assert res.returncode == 0, res.stderr[-2000:]
    return png
