"""Tests of the log's words: a process prints its log as its command prints its messages."""

from __future__ import annotations

import logging
import subprocess
import sys

from fishswarm.actors.logs import DEFAULT_PREFIX, CommandFormatter, log_prefix


def _record(level: int, message: str, *args: object, exc: bool = False) -> logging.LogRecord:
    exc_info = None
    if exc:
        try:
            raise RuntimeError("the fins jammed")
        except RuntimeError:
            exc_info = sys.exc_info()
    return logging.LogRecord("fishswarm.actors.world", level, __file__, 1, message, args, exc_info)


def test_a_warning_reads_as_the_commands_own() -> None:
    formatter = CommandFormatter("fishswarm run")
    record = _record(logging.WARNING, "fish %d back at tick %d (lost at tick %d)", 10, 6, 4)
    assert formatter.format(record) == (
        "fishswarm run: warning: fish 10 back at tick 6 (lost at tick 4)"
    )
    assert formatter.format(_record(logging.ERROR, "gone")) == "fishswarm run: error: gone"


def test_lower_levels_name_their_logger() -> None:
    formatter = CommandFormatter("fishswarm fish")
    assert formatter.format(_record(logging.DEBUG, "tick %d", 3)) == (
        "fishswarm fish: debug: fishswarm.actors.world: tick 3"
    )


def test_a_traceback_follows_its_message() -> None:
    lines = CommandFormatter("fishswarm run").format(_record(logging.ERROR, "x", exc=True))
    first, *rest = lines.splitlines()
    assert first == "fishswarm run: error: x"
    assert rest[0] == "Traceback (most recent call last):"
    assert rest[-1] == "RuntimeError: the fins jammed"


def test_a_process_prints_with_its_prefix_and_passes_it_on() -> None:
    script = (
        "import logging\n"
        "from fishswarm.actors.logs import configure_logging, log_prefix\n"
        "print(log_prefix())\n"
        "configure_logging(prefix='fishswarm run', level='WARNING')\n"
        "logging.getLogger('fishswarm.actors.roster').warning('fish %d lost at tick %d', 3, 7)\n"
        "logging.getLogger('fishswarm.actors.roster').info('not shown')\n"
        "print(log_prefix())\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, timeout=60, check=True
    )
    assert done.stdout.splitlines() == [DEFAULT_PREFIX, "fishswarm run"]
    assert done.stderr.splitlines() == ["fishswarm run: warning: fish 3 lost at tick 7"]


def test_the_prefix_here_is_the_default_under_a_foreign_handler() -> None:
    # pytest's own capture owns the root logger in this process.
    assert log_prefix() == DEFAULT_PREFIX
