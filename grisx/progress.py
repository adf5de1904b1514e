"""Progress of long work on stderr: a bar on a terminal, a plain line every ~10 s anywhere else.

On a terminal, `tqdm <https://tqdm.github.io>`_ draws a one-line bar with the
rate and an ETA. Off a terminal (a log file, CI, a pipe) a bar would be a
stream of carriage returns, so a plain line is printed instead, at most every
:data:`LINE_SECONDS`, with the same ETA::

    cornell-box pt: 12/40 spp (30%), 00:21 elapsed, ETA 00:49

Work that ends within :data:`LINE_SECONDS` prints nothing off a terminal, and
work that ends within :data:`BAR_DELAY_SECONDS` draws no bar on one.
Renders (frames, and samples per pixel within a frame), references and
studies all report through :class:`Progress`.
"""

from __future__ import annotations

import io
import os
import sys
import time
from typing import Any, TextIO

from tqdm import tqdm

__all__ = ["Progress", "LINE_SECONDS", "BAR_DELAY_SECONDS"]

#: seconds between two plain progress lines off a terminal
LINE_SECONDS = 10.0
#: seconds before the bar appears on a terminal: quick work (and input refused at once) draws none
BAR_DELAY_SECONDS = 0.5

_BAR = "{desc} [{bar:24}] {n_fmt}/{total_fmt} {unit} {elapsed} eta {remaining}{postfix}"
_LINE = "{desc}: {n_fmt}/{total_fmt} {unit} ({percentage:.0f}%), {elapsed} elapsed, ETA {remaining}{postfix}"


def _isatty(stream: Any) -> bool:
    isatty = getattr(stream, "isatty", None)
    try:
        return bool(isatty and isatty())
    except ValueError:  # a closed stream
        return False


def _columns(stream: Any) -> int:
    try:
        return os.get_terminal_size(stream.fileno()).columns
    except (AttributeError, OSError, ValueError, io.UnsupportedOperation):
        return 0


class Progress:
    """Progress of ``total`` units of work (``unit``: "frame", "spp", "run", ...) on ``stream`` (stderr).

    ``enabled=None``: a bar if the stream is a terminal (after :data:`BAR_DELAY_SECONDS`), plain lines
    every :data:`LINE_SECONDS` otherwise; ``True``: always the bar, at once; ``False``: silent.
    """

    def __init__(self, total: int, desc: str = "", *, unit: str = "it", enabled: bool | None = None,
                 stream: TextIO | None = None) -> None:
        self.stream = stream if stream is not None else sys.stderr
        self.total, self.desc, self.unit = max(int(total), 1), desc, unit
        self.mode = "off" if enabled is False else "bar" if enabled or _isatty(self.stream) else "lines"
        self.start = self._last_line = time.perf_counter()
        self._n, self._note, self._lines, self._shown = 0, "", 0, 0
        self._bar = None
        if self.mode == "bar":
            # a terminal of unknown size (0x0, e.g. a pty without a window: tqdm would hide the bar): 100x20
            sized = _columns(self.stream) > 0
            self._bar = tqdm(total=self.total, desc=desc, unit=unit, file=self.stream, ascii=" #", leave=True,
                             bar_format=_BAR, dynamic_ncols=sized, ncols=None if sized else 100, nrows=None if sized else 20,
                             delay=0.0 if enabled else BAR_DELAY_SECONDS)

    @property
    def done(self) -> int:
        return self._n

    @done.setter
    def done(self, value: int) -> None:
        self.update(int(value) - self._n)

    def update(self, n: int = 1, note: str = "") -> None:
        """``n`` more units done; ``note`` (e.g. the current error) is shown after the ETA."""
        self._n = min(self._n + int(n), self.total)
        self._note = note[:40] if note else self._note
        if self._bar is not None:
            if note:
                self._bar.set_postfix_str(self._note, refresh=False)
            self._bar.update(self._n - self._bar.n)
        elif self.mode == "lines" and self._n != self._shown:
            now = time.perf_counter()
            if now - self._last_line >= LINE_SECONDS:
                self._line(now)

    def restart(self) -> None:
        """Start the clock again (nothing done yet): what came before, e.g. compiling kernels, is no part of the ETA."""
        if self._n:
            return
        self.start = self._last_line = time.perf_counter()
        if self._bar is not None:
            self._bar.reset(self.total)

    def __call__(self, done: int, total: int, unit: str | None = None) -> None:
        """``done`` of ``total`` units (a callback for :func:`grisx.render.driver.render` and references);
        0 done before anything was done restarts the clock."""
        if int(done) == 0:
            self.restart()
        if unit is not None and unit != self.unit:
            self.unit = unit
            if self._bar is not None:
                self._bar.unit = unit
        if int(total) != self.total:
            self.total = max(int(total), 1)
            if self._bar is not None:
                self._bar.total = self.total
        self.done = done

    def _line(self, now: float) -> None:
        self._last_line, self._shown = now, self._n
        self._lines += 1
        postfix = self._note or None
        self.stream.write(tqdm.format_meter(self._n, self.total, now - self.start, prefix=self.desc, unit=self.unit,
                                            postfix=postfix, bar_format=_LINE) + "\n")
        self.stream.flush()

    def close(self) -> None:
        """End the bar (a newline), or, off a terminal, a last line if earlier lines were printed."""
        if self._bar is not None:
            self._bar.close()
            self._bar = None
        elif self.mode == "lines" and self._lines and self._shown != self._n:
            self._line(time.perf_counter())
        self.mode = "off"

    def __enter__(self) -> Progress:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()
