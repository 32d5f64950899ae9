"""``fishswarm behaviors``: the behaviours there are, each with its own settings."""

from __future__ import annotations

import argparse

from fishswarm.behaviors.conformance import check_decisions
from fishswarm.behaviors.registry import behavior_named, names, plugin_failures, plugin_source
from fishswarm.sim.scenario import ConfigError, Scenario, as_written, own_setting_from_text


def behaviors(args: argparse.Namespace, scenario: Scenario | None) -> int:
    """List fishswarm's behaviours and other packages': name, what it does, where it comes
    from, and its own settings with their defaults (what ``--behavior-setting`` may set);
    with ``--check NAME``, check that one against the rules every behaviour keeps."""
    if args.check is not None:
        return _check(args.check, args.behavior_settings or [])
    if args.behavior_settings:
        raise ConfigError("--behavior-setting goes with --check NAME")
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


def _check(name: str, given: list[tuple[str, str]]) -> int:
    settings = {setting: own_setting_from_text(name, setting, text) for setting, text in given}
    params = Scenario(behavior=name, behavior_settings=tuple(settings.items())).fish_params()
    found = check_decisions(params)
    print(f"{name}: checked on random perceptions (seeded)")
    broken = dict(found.problems)
    for check in found.checks:
        print(f"  {'FAILED' if check in broken else 'ok':<6}  {check}")
        if check in broken:
            print(f"          {broken[check]}")
    if found.problems:
        print(f"{name} breaks {len(found.problems)} of the {len(found.checks)} rules")
        return 1
    print(f"{name} keeps the rules")
    return 0
