"""``fishswarm behaviors``: the behaviours there are, each with its own settings."""

from __future__ import annotations

import argparse

from fishswarm.behaviors.registry import behavior_named, names, plugin_failures, plugin_source
from fishswarm.sim.scenario import Scenario, as_written


def behaviors(args: argparse.Namespace, scenario: Scenario | None) -> int:
    """List fishswarm's behaviours and other packages': name, what it does, where it comes
    from, and its own settings with their defaults (what ``--behavior-setting`` may set)."""
    known = names()
    width = max(len(name) for name in known)
    for name in known:
        family = behavior_named(name)
        source = plugin_source(name)
        print(f"{name:<{width}}  {family.summary}" + (f"  [{source}]" if source else ""))
        if family.settings:
            settings = ", ".join(
                f"{setting} = {as_written(default)}" for setting, default in family.settings.items()
            )
            print(f"{'':<{width}}  its settings (--behavior-setting NAME=VALUE): {settings}")
    for failure in plugin_failures():  # also said as a warning when the command started
        print(f"left out: {failure}")
    return 0
