"""Tests of the behaviour table: other packages' behaviours, added through entry points, and
the example package's behaviour by hand."""

from __future__ import annotations

import importlib.metadata
from collections.abc import Iterator, Mapping
from typing import Any

import numpy as np
import pytest

from fishswarm.behaviors import registry
from fishswarm.behaviors.core import (
    Behavior,
    FishMemory,
    Inbox,
    NoMemory,
    Perception,
    decide,
)
from fishswarm.behaviors.registry import (
    PLUGIN_GROUP,
    behavior_named,
    fish_params,
    names,
    plugin_failures,
    register,
)
from fishswarm.sim.scenario import Scenario
from tests.behaviors import example_plugin
from tests.behaviors.signal_behavior import SIGNAL

OWN = ("dispersion", "aggregation", "orbit", "milling", "waltz", "replica", "formation")


@pytest.fixture
def points(monkeypatch: pytest.MonkeyPatch) -> Iterator[list[importlib.metadata.EntryPoint]]:
    """The entry points the table reads, as a test sets them; the table as fishswarm's own
    behaviours alone, not read yet, and put back as it was afterwards."""
    saved = dict(registry.BEHAVIORS)
    given: list[importlib.metadata.EntryPoint] = []

    def entry_points(*, group: str) -> list[importlib.metadata.EntryPoint]:
        return [point for point in given if point.group == group]

    monkeypatch.setattr(importlib.metadata, "entry_points", entry_points)
    monkeypatch.setattr(registry, "_plugins_read", False)
    monkeypatch.setattr(registry, "_plugin_failures", [])
    monkeypatch.setattr(registry, "_plugin_sources", {})
    for name in set(registry.BEHAVIORS) - set(OWN):
        del registry.BEHAVIORS[name]
    yield given
    registry.BEHAVIORS.clear()
    registry.BEHAVIORS.update(saved)


def _point(name: str, value: str, group: str = PLUGIN_GROUP) -> importlib.metadata.EntryPoint:
    return importlib.metadata.EntryPoint(name, value, group)


def test_another_packages_behaviour_is_listed_after_fishswarms_own_and_found_by_name(
    points: list[importlib.metadata.EntryPoint],
) -> None:
    points.append(_point("nearest", "fishswarm_nearest:NEAREST"))
    points.append(_point("elsewhere", "fishswarm_nearest:NEAREST", group="other.group"))
    example_plugin.nearest()  # its folder importable, as an install would make it
    assert names() == (*OWN, "nearest")
    assert behavior_named("nearest") is example_plugin.nearest()
    assert plugin_failures() == ()
    # A scenario, and so every command, takes it by name, with its own settings.
    scenario = Scenario(behavior="nearest", behavior_settings=(("distance", 1),))
    assert scenario.behavior_settings == (("distance", 1.0),)
    steering = scenario.fish_params().steering
    assert (steering.distance, steering.cruise) == (1.0, pytest.approx(0.52))


def test_a_lookup_of_fishswarms_own_behaviour_reads_no_other_package(
    points: list[importlib.metadata.EntryPoint],
) -> None:
    points.append(_point("nearest", "fishswarm_nearest:NEAREST"))
    assert behavior_named("orbit").name == "orbit"
    assert "nearest" not in registry.BEHAVIORS  # read when a name is not found, or listed
    assert behavior_named("nearest").name == "nearest"


@pytest.mark.parametrize(
    ("name", "value", "reason"),
    [
        (
            "gone",
            "no_such_package_here:GONE",
            "loading it raised ModuleNotFoundError: No module named 'no_such_package_here'",
        ),
        ("answer", "math:pi", "it is a float, not a fishswarm.behaviors.core.Behavior"),
        (
            "signal",
            "tests.behaviors.signal_behavior:SIGNAL",
            "the behaviour calls itself 'test-signal': name the entry point as the behaviour",
        ),
        (
            "orbit",
            "fishswarm.behaviors.orbit:MILLING",
            "the behaviour calls itself 'milling'",
        ),
        (
            "milling",
            "fishswarm.behaviors.orbit:MILLING",
            "a behaviour of that name is there already (fishswarm's own, or another package's)",
        ),
    ],
)
def test_a_behaviour_that_cannot_be_added_is_left_out_and_said_why(
    points: list[importlib.metadata.EntryPoint], name: str, value: str, reason: str
) -> None:
    points.append(_point(name, value))
    points.append(_point("nearest", "fishswarm_nearest:NEAREST"))
    example_plugin.nearest()
    assert names() == (*OWN, "nearest")  # the others still come in
    (failure,) = plugin_failures()
    assert (failure.name, failure.source) == (name, value)
    assert failure.reason.startswith(reason), failure.reason
    assert str(failure) == f"the behaviour {name!r} ({value}) is left out: {failure.reason}"
    assert behavior_named("milling").name == "milling"  # fishswarm's own, unchanged


def test_a_behaviour_with_a_controller_or_spawn_radius_fishswarm_lacks_is_left_out(
    points: list[importlib.metadata.EntryPoint], monkeypatch: pytest.MonkeyPatch
) -> None:
    import tests.behaviors.signal_behavior as signal

    bad_controller = Behavior(**{**vars(SIGNAL), "controller": "p"})
    no_radius = Behavior(**{**vars(SIGNAL), "spawn_radius": 0.0})
    monkeypatch.setattr(signal, "BAD_CONTROLLER", bad_controller, raising=False)
    monkeypatch.setattr(signal, "NO_RADIUS", no_radius, raising=False)
    points.append(_point("test-signal", "tests.behaviors.signal_behavior:BAD_CONTROLLER"))
    assert names() == OWN
    assert plugin_failures()[0].reason == ("its controller must be one of homing, pid, got 'p'")
    monkeypatch.setattr(registry, "_plugins_read", False)
    monkeypatch.setattr(registry, "_plugin_failures", [])
    points[:] = [_point("test-signal", "tests.behaviors.signal_behavior:NO_RADIUS")]
    assert names() == OWN
    assert plugin_failures()[0].reason == (
        "its spawn_radius must be a positive number of metres, got 0.0"
    )


@pytest.mark.parametrize(
    ("settings", "reason"),
    [
        (
            {"two words": 1.0},
            "its setting 'two words' is not a name (letters, digits and _, at most 64 of them)",
        ),
        ({"gain": float("nan")}, "its setting gain's default must be a finite number, text or"),
        ({"gain": [1, 2]}, "its setting gain's default must be a finite number, text or"),
        (
            {"gain": np.float64(1.0)},
            "its setting gain's default must be a finite number, text or true or false, of "
            "Python's own types (float(...) of a NumPy number), got np.float64(1.0) (float64)",
        ),
        (
            [("gain", 1.0)],
            "its settings must be a dict of names and defaults, e.g. {'gain': 0.5}, got a list",
        ),
        # More than a run's settings message carries: every run of it would fail.
        ({f"s{i}": 1.0 for i in range(65)}, "it has 65 settings: at most 64 can be sent"),
        ({"label": "x" * 4097}, "its setting label's default is longer than 4096 characters"),
    ],
)
def test_a_behaviour_whose_own_settings_are_not_plain_values_is_left_out(
    points: list[importlib.metadata.EntryPoint],
    monkeypatch: pytest.MonkeyPatch,
    settings: object,
    reason: str,
) -> None:
    import tests.behaviors.signal_behavior as signal

    odd = Behavior(**{**vars(SIGNAL), "settings": settings})
    monkeypatch.setattr(signal, "ODD_SETTINGS", odd, raising=False)
    points.append(_point("test-signal", "tests.behaviors.signal_behavior:ODD_SETTINGS"))
    assert names() == OWN  # and the rest of fishswarm as before
    assert plugin_failures()[0].reason.startswith(reason), plugin_failures()[0].reason
    with pytest.raises(
        ValueError, match=r"'test-signal' cannot be registered: (its setting|it has 65)"
    ):
        register(odd)
    assert behavior_named("dispersion").name == "dispersion"


def test_a_behaviour_whose_parameters_fail_otherwise_than_by_a_bad_value_is_named(
    points: list[importlib.metadata.EntryPoint],
) -> None:
    def parameters(settings: Mapping[str, Any]) -> object:
        return settings["behavior_settings"]["gian"]

    register(Behavior(**{**vars(SIGNAL), "parameters": parameters}))
    with pytest.raises(
        ValueError,
        match=r"^the behaviour 'test-signal' could not make its parameters from the settings: "
        r"KeyError: 'gian'$",
    ):
        fish_params({"behavior": "test-signal"})


def test_registering_a_name_another_package_took_is_refused(
    points: list[importlib.metadata.EntryPoint],
) -> None:
    points.append(_point("test-signal", "tests.behaviors.signal_behavior:SIGNAL"))
    with pytest.raises(ValueError, match="a behaviour called 'test-signal' is registered"):
        register(Behavior(**{**vars(SIGNAL), "summary": "another"}))
    assert behavior_named("test-signal") is SIGNAL


def _perception(*neighbors: tuple[float, float, float]) -> Perception:
    """One fish that sees ``neighbors`` (body frame, m), one padding row after them."""
    rows = np.zeros((1, len(neighbors) + 1, 3))
    rows[0, : len(neighbors)] = np.reshape(neighbors, (-1, 3))
    mask = np.arange(len(neighbors) + 1)[None, :] < len(neighbors)
    return Perception(
        np.zeros(1), np.full(1, 0.5), rows, mask, np.zeros((1, 0, 3)), np.zeros((1, 0), bool)
    )


@pytest.mark.parametrize(
    ("neighbors", "target"),
    [
        # Nearest 0.5 m ahead, 0.26 m to keep: 0.24 m towards it (the one 0.9 m off ignored).
        ([(0.5, 0.0, 0.0), (0.0, 0.9, 0.0)], (0.24, 0.0, 0.0)),
        # 0.1 m to the right (+y; x ahead, z down): 0.16 m away from it, to the left.
        ([(0.0, 0.1, 0.0), (0.6, 0.0, 0.0)], (0.0, -0.16, 0.0)),
        # 0.3-0.4-0.5 triangle: 0.24 m gap to close along (0.6, 0.8, 0).
        ([(0.3, 0.4, 0.0)], (0.144, 0.192, 0.0)),
        # Nobody seen, or a neighbour where the fish is: straight on, 4 body lengths.
        ([], (0.52, 0.0, 0.0)),
        ([(0.0, 0.0, 0.0)], (0.52, 0.0, 0.0)),
    ],
)
def test_the_example_behaviour_keeps_the_nearest_neighbour_at_its_distance(
    neighbors: list[tuple[float, float, float]], target: tuple[float, float, float]
) -> None:
    family = example_plugin.nearest()
    params = family.parameters({"behavior_settings": family.settings})
    memory, steering = family.steer(
        NoMemory(), _perception(*neighbors), Inbox.empty(1), params=params
    )
    np.testing.assert_allclose(steering.target[0], target, atol=1e-12)
    assert memory == NoMemory() and steering.led.all() and not steering.outbox.mask.any()


def test_the_example_behaviour_decides_fins_and_refuses_a_bad_distance() -> None:
    example_plugin.registered()
    params = fish_params({"behavior": "nearest"})  # its own settings' defaults
    memory = FishMemory.fresh(params, 1)
    _, decision = decide(memory, _perception((0.0, 0.5, 0.0)), Inbox.empty(1), params=params)
    # Homing: the neighbour 90° to the right; a turn to the right on the left pectoral fin,
    # at min(1, 0.6 + 90/180); no caudal beyond the 20° band, the dorsal fin left off.
    np.testing.assert_allclose(decision.fins[0], [0.0, 0.0, 1.0, 0.0])
    with pytest.raises(ValueError, match=r"distance must be a positive length in m, got -1\.0"):
        fish_params({"behavior": "nearest", "behavior_settings": {"distance": -1.0}})


def test_a_behaviour_worker_processes_could_not_import_is_left_out(
    points: list[importlib.metadata.EntryPoint], monkeypatch: pytest.MonkeyPatch
) -> None:
    import tests.behaviors.signal_behavior as signal

    nested = Behavior(**{**vars(SIGNAL), "parameters": lambda settings: None})
    monkeypatch.setattr(signal, "NESTED", nested, raising=False)
    points.append(_point("test-signal", "tests.behaviors.signal_behavior:NESTED"))
    assert names() == OWN
    assert plugin_failures()[0].reason.startswith(
        "its parts must be functions and classes at the top level of a module, not lambdas or "
        "nested functions: worker processes import them by name (AttributeError: Can't pickle "
        "local object "
    ), plugin_failures()[0].reason
