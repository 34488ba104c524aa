"""Progress on the command line: one bar per step on a terminal, plain lines (every tenth) in a log; messages on their own line."""
from __future__ import annotations

import sys
from types import TracebackType
from typing import TextIO

from tqdm import tqdm

from planner.core.steps import Progress

LABEL_WIDTH = 14
PLAIN_STEP = 10  # percent: in a log, a line each time a step gets this much further


class Bars:
    """Progress bars of one step at a time on `stream` (stderr by default); use as a context manager so the last bar ends."""

    def __init__(self, stream: TextIO | None = None):
        self.stream = stream if stream is not None else sys.stderr
        self.tty = self.stream.isatty()
        self._bar: tqdm | None = None
        self._label = ""
        self._printed: int | None = None  # the last percentage printed as a plain line (None: none yet)

    def __enter__(self) -> Bars:
        return self

    def __exit__(self, kind: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None) -> None:
        self.close()

    def start(self, label: str) -> Progress:
        """End the current bar and begin one for `label`; returns its `(fraction, message)` callback."""
        self.close()
        self._label, self._printed = label, None
        if self.tty:
            self._bar = tqdm(total=100, file=self.stream, leave=True, dynamic_ncols=True,
                             bar_format=f"{label:<{LABEL_WIDTH}} {{percentage:3.0f}}% |{{bar:24}}| {{desc}}")
        return self.report

    def report(self, fraction: float, message: str = "") -> None:
        """Move the current bar to `fraction` (0..1) with `message`; it ends its line at 1."""
        percent = round(100 * min(max(fraction, 0.0), 1.0))
        if self._bar is not None:
            self._bar.n = percent
            self._bar.set_description_str(message, refresh=False)
            self._bar.refresh()
        elif not self.tty and (self._printed is None or percent >= self._printed + PLAIN_STEP or (percent == 100 > self._printed)):
            self._printed = percent
            print(f"{self._label}: {percent:3d}% {message}".rstrip(), file=self.stream, flush=True)
        if fraction >= 1.0:
            self.close()

    def say(self, text: str) -> None:
        """Print a message on its own line, above a bar that is running (which is drawn again below it)."""
        if self._bar is not None:
            tqdm.write(text, file=self.stream)
        else:
            print(text, file=self.stream, flush=True)

    def close(self) -> None:
        """End the current bar's line (a finished or an interrupted step alike)."""
        if self._bar is not None:
            self._bar.close()
            self._bar = None
