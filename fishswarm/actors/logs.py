"""How fishswarm's processes print their log: in the words of the command that runs them.

A warning from the world of ``fishswarm run`` reads ``fishswarm run: warning: fish 10 back at
tick 6 (lost at tick 4)``, the way the command's own warnings and errors read, and a worker
process of that run prints its fish's warnings the same way. Warnings and errors say in
their own words what they are about; the lower levels, for whoever debugs, also name the
logger (``fishswarm run: debug: fishswarm.actors.world: …``).
"""

from __future__ import annotations

import logging

DEFAULT_PREFIX = "fishswarm"


class CommandFormatter(logging.Formatter):
    """Formats a record as ``<prefix>: <level>: <message>`` (below warnings, the logger's name
    before the message), a traceback after it."""

    def __init__(self, prefix: str) -> None:
        super().__init__()
        self.prefix = prefix

    def format(self, record: logging.LogRecord) -> str:
        record.message = record.getMessage()
        level = record.levelname.lower()
        if record.levelno >= logging.WARNING:
            text = f"{self.prefix}: {level}: {record.message}"
        else:
            text = f"{self.prefix}: {level}: {record.name}: {record.message}"
        if record.exc_info and not record.exc_text:
            record.exc_text = self.formatException(record.exc_info)
        if record.exc_text:
            text = f"{text}\n{record.exc_text}"
        if record.stack_info:
            text = f"{text}\n{self.formatStack(record.stack_info)}"
        return text


def configure_logging(*, prefix: str, level: str | int) -> None:
    """Print this process's log to stderr as ``<prefix>: <level>: <message>``.

    Args:
        prefix: what the command's own messages start with, e.g. ``fishswarm run``.
        level: the lowest level printed (a name such as ``"WARNING"``, or a number).
    """
    handler = logging.StreamHandler()
    handler.setFormatter(CommandFormatter(prefix))
    # As logging.basicConfig does, nothing changes where the root logger has its handlers
    # already (a test's log capture, an embedding program's own).
    logging.basicConfig(level=level, handlers=[handler])


def log_prefix() -> str:
    """The prefix this process prints its log with, for a process it starts to print the
    same: :data:`DEFAULT_PREFIX` when :func:`configure_logging` was not called."""
    for handler in logging.getLogger().handlers:
        if isinstance(handler.formatter, CommandFormatter):
            return handler.formatter.prefix
    return DEFAULT_PREFIX
