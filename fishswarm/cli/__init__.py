"""The ``fishswarm`` command: parsers in :mod:`.parsers`, handlers in :mod:`.swarm`,
:mod:`.study` and :mod:`.learn`."""

from __future__ import annotations

import importlib
import sys
from collections.abc import Sequence

from fishswarm.actors.logs import configure_logging
from fishswarm.actors.shared_memory import release_shared_memory_at_exit
from fishswarm.behaviors.registry import plugin_failures
from fishswarm.cli.common import UserError
from fishswarm.cli.parsers import build_parser, scenario_from
from fishswarm.sim.allocator import tune_allocator
from fishswarm.sim.openmp import tune_openmp
from fishswarm.sim.scenario import ConfigError

HANDLERS = {
    "run": ("swarm", "run"),
    "fish": ("swarm", "fish"),
    "robot": ("robot", "robot"),
    "robots": ("robot", "robots"),
    "world": ("swarm", "world"),
    "channel": ("swarm", "channel"),
    "observe": ("swarm", "observe"),
    "view": ("view", "view"),
    "router": ("swarm", "router"),
    "secure": ("swarm", "secure"),
    "formation": ("swarm", "formation"),
    "control": ("swarm", "control"),
    "export": ("swarm", "export"),
    "learn": ("learn", "learn_command"),
    "behaviors": ("behaviors", "behaviors"),
    "experiment": ("study", "experiment"),
    "plot": ("study", "plot"),
    "animate": ("study", "animate"),
}
"""Each command's handler: (module of :mod:`fishswarm.cli`, function). Only the command's
own module is imported: ``fishswarm robot`` on a BlueBot's Pi must not import the base
station's (scipy, mcap)."""


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``fishswarm`` console script."""
    parser = build_parser()
    args = parser.parse_args(argv)
    configure_logging(prefix=f"fishswarm {args.command}", level=args.log_level)
    if args.command != "behaviors":  # which lists them itself
        for failure in plugin_failures():  # read as the parser listed the behaviours
            print(f"fishswarm {args.command}: warning: {failure}", file=sys.stderr)
    if args.command != "robot":  # a robot's small process keeps glibc's own settings
        tune_allocator()
        tune_openmp()
    # Zenoh leaves a shared-memory file behind for each process that sent through it.
    release_shared_memory_at_exit()
    module, function = HANDLERS[args.command]
    handler = getattr(importlib.import_module(f"fishswarm.cli.{module}"), function)
    try:
        scenario = scenario_from(args) if hasattr(args, "config") else None
        code = int(handler(args, scenario))
    except ConfigError as error:
        parser.exit(2, f"fishswarm {args.command}: error: {error}\n")
    except UserError as error:
        print(f"fishswarm {args.command}: error: {error}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("fishswarm: interrupted", file=sys.stderr)
        return 130
    return code


if __name__ == "__main__":
    sys.exit(main())
