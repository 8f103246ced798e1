"""A dependency-free progress bar on stderr for long runs (Monte Carlo, sweeps, soaks)."""

from __future__ import annotations

import sys
import time
from typing import TextIO


class Progress:
    """``with Progress(total, "runs") as bar: ... bar.advance()`` prints ``[####    ] 12/50 runs``.

    Redraws at most every 0.1 s; on a non-terminal stream it prints a line every 10 %.
    """

    def __init__(self, total: int, label: str = "", stream: TextIO | None = None,
                 enabled: bool = True) -> None:
        self.total = max(int(total), 1)
        self.label = label
        self.stream = stream if stream is not None else sys.stderr
        self.enabled = enabled
        self.done = 0
        self.start = time.monotonic()
        self._last_draw = 0.0
        self._last_decile = -1
        self._tty = bool(getattr(self.stream, "isatty", lambda: False)())

    def __enter__(self) -> Progress:
        self._draw(force=True)
        return self

    def __exit__(self, *exc) -> None:
        self._draw(force=True)
        if self.enabled and self._tty:
            self.stream.write("\n")
            self.stream.flush()

    def advance(self, n: int = 1) -> None:
        self.done = min(self.done + n, self.total)
        self._draw()

    def _line(self) -> str:
        frac = self.done / self.total
        elapsed = time.monotonic() - self.start
        # no estimate before the first item is done (not "nan"), none needed after the last
        eta = ("eta ?" if frac == 0 else "done" if frac >= 1
               else f"eta {elapsed / frac - elapsed:5.1f}s")
        bar = "#" * int(30 * frac)
        return (f"[{bar:<30}] {self.done}/{self.total} {self.label}  "
                f"{elapsed:5.1f}s elapsed, {eta}")

    def _draw(self, force: bool = False) -> None:
        if not self.enabled:
            return
        now = time.monotonic()
        if self._tty:
            if force or now - self._last_draw >= 0.1 or self.done == self.total:
                self.stream.write("\r" + self._line())
                self.stream.flush()
                self._last_draw = now
        else:
            decile = int(10 * self.done / self.total)
            if force and self.done == 0 or decile > self._last_decile:
                self._last_decile = decile
                self.stream.write(self._line() + "\n")
                self.stream.flush()
