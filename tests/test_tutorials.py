"""Every tutorial runs as a plain script in quick mode and writes at least one figure.

Tutorials are percent-format scripts (``tutorials/NN_topic.py``); each honours
``GRISX_QUICK=1`` (few trials) and ``GRISX_TUTORIAL_OUT`` (figure directory).
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

TUTORIALS_DIR = Path(__file__).resolve().parents[1] / "tutorials"
TUTORIALS = sorted(TUTORIALS_DIR.glob("[0-9][0-9]_*.py"))


def test_tutorials_exist() -> None:
    assert TUTORIALS, f"no tutorials found in {TUTORIALS_DIR}"


@pytest.mark.parametrize("script", TUTORIALS, ids=[p.stem for p in TUTORIALS])
def test_tutorial_runs_in_quick_mode(script: Path, tmp_path: Path) -> None:
    out = tmp_path / "figures"
    env = dict(os.environ, GRISX_QUICK="1", GRISX_TUTORIAL_OUT=str(out), MPLBACKEND="Agg")
    proc = subprocess.run(
        [sys.executable, str(script)],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert proc.returncode == 0, f"{script.name} exited with {proc.returncode}\n--- stdout ---\n{proc.stdout[-4000:]}\n--- stderr ---\n{proc.stderr[-4000:]}"
    pngs = sorted(out.glob("*.png"))
    assert pngs, f"{script.name} wrote no PNG into {out}"
