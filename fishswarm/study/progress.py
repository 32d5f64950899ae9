"""Text for people: progress lines for long runs (a bar, one updating line on a terminal,
plain lines in logs) and short lists of fish ids."""

from __future__ import annotations

import sys
from typing import TextIO


def bar(done: int, total: int, width: int = 20) -> str:
    """``[#####...............]``: ``done`` of ``total`` as a bar of ``width`` cells."""
    filled = round(width * min(done, total) / total) if total > 0 else 0
    return f"[{'#' * filled}{'.' * (width - filled)}]"


class ProgressLine:
    """Writes progress lines: rewritten in place on a terminal, one per line otherwise.

    Args:
        stream: where to write (standard error by default).
    """

    def __init__(self, stream: TextIO | None = None) -> None:
        self.stream = sys.stderr if stream is None else stream
        self.tty = self.stream.isatty()
        self._open = False

    def show(self, line: str, *, last: bool = False) -> None:
        """Show a line; ``last`` ends the updating line on a terminal."""
        if self.tty:
            self.stream.write("\r" + line + ("\n" if last else ""))
            self._open = not last
        else:
            self.stream.write(line + "\n")
        self.stream.flush()

    def close(self) -> None:
        """End an updating line on a terminal, if one is open (before other output: after
        Ctrl-C, or a run that ended before its last tick)."""
        if self._open:
            self.stream.write("\n")
            self.stream.flush()
            self._open = False


def ids_text(ids: list[int], limit: int = 20) -> str:
    """``0, 1, 2 …``: at most ``limit`` ids, for messages."""
    return ", ".join(map(str, ids[:limit])) + (" …" if len(ids) > limit else "")
