"""What every tutorial sets up first: quick mode, device, output folder, figure saving.

The tutorials in ``tutorials/`` are percent-format scripts that also open as
notebooks. They share one convention, kept here so it is written once:

* ``GRISX_QUICK=1`` (or ``--quick`` on the command line) selects small trial
  counts — the test suite runs every tutorial that way;
* ``GRISX_DEVICE`` (default ``cpu``) is the Warp device of every kernel and
  array of the tutorial;
* ``GRISX_TUTORIAL_OUT`` is where figures go (default ``tutorials/out/``);
* outside a Jupyter kernel matplotlib draws off-screen (Agg) and figures are
  only written; inside one they are also shown inline.

Usage, at the top of a tutorial (before ``matplotlib.pyplot`` is imported)::

    from grisx.tutorial import tutorial_setup
    setup = tutorial_setup(globals().get("__file__"))
    import matplotlib.pyplot as plt
    QUICK, DEVICE, OUT, save = setup.quick, setup.device, setup.out, setup.save
"""

from __future__ import annotations

import dataclasses
import os
import sys
import time
from pathlib import Path
from typing import Any

__all__ = ["TutorialSetup", "tutorial_setup", "in_notebook"]

_FALSE = ("", "0", "false", "no")


def in_notebook() -> bool:
    """True inside a Jupyter kernel (then figures are shown inline)."""
    try:
        from IPython import get_ipython
    except ImportError:
        return False
    shell = get_ipython()
    return shell is not None and "IPKernelApp" in getattr(shell, "config", {})


@dataclasses.dataclass
class TutorialSetup:
    quick: bool
    device: str
    out: Path
    interactive: bool
    start: float

    def save(self, fig: Any, name: str) -> None:
        """Write a figure to ``out``; show it inline in a notebook."""
        import matplotlib.pyplot as plt

        path = self.out / name
        fig.savefig(path, dpi=120, bbox_inches="tight")
        print(f"wrote {path}")
        if self.interactive:
            plt.show()
        else:
            plt.close(fig)


def _default_out(script: str | None) -> Path:
    if script:  # run as a script: beside it
        return Path(script).resolve().parent / "out"
    # in a notebook: relative to where it was opened
    return Path("out") if Path.cwd().name == "tutorials" else Path("tutorials") / "out"


def tutorial_setup(script: str | None = None) -> TutorialSetup:
    """Read the environment, pick the matplotlib backend and the Warp device, create the output folder."""
    import matplotlib
    import warp as wp

    interactive = in_notebook()
    if not interactive:
        matplotlib.use("Agg")
    quick = os.environ.get("GRISX_QUICK", "").strip().lower() not in _FALSE or "--quick" in sys.argv
    device = os.environ.get("GRISX_DEVICE", "cpu")
    wp.set_device(device)
    out = Path(os.environ.get("GRISX_TUTORIAL_OUT") or _default_out(script))
    out.mkdir(parents=True, exist_ok=True)
    return TutorialSetup(quick=quick, device=device, out=out, interactive=interactive, start=time.perf_counter())
