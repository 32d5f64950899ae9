"""Tests of the rules check a behaviour's author runs: it passes every behaviour fishswarm
ships and the example's, and catches each rule broken."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from fishswarm.behaviors.conformance import check_decisions
from fishswarm.behaviors.core import (
    Behavior,
    FishParams,
    Inbox,
    NoMemory,
    Perception,
    Steering,
    no_memory,
    steady,
)
from fishswarm.behaviors.registry import BEHAVIORS
from fishswarm.sim.scenario import Scenario
from tests.behaviors import example_plugin


@pytest.mark.parametrize("name", [*BEHAVIORS, "nearest"])
def test_every_behaviour_shipped_and_the_examples_keep_the_rules(name: str, tmp_path: Path) -> None:
    example_plugin.registered()
    model = tmp_path / "best_replica.npz"
    np.savez(model, weights=np.random.default_rng(0).normal(0, 1, 21), settings="{}")
    settings = {"model": str(model)} if name == "replica" else {}
    found = check_decisions(Scenario(behavior=name, **settings).fish_params())  # type: ignore[arg-type]
    assert found.problems == ()
    assert len(found.checks) == 4


def _ahead(count: int) -> np.ndarray:
    return np.tile([0.3, 0.0, 0.0], (count, 1))


def _school_mean(
    memory: NoMemory, perception: Perception, inbox: Inbox, *, params: None
) -> tuple[NoMemory, Steering]:
    # Every fish steers by what the whole batch sees: not a fish's own decision.
    seen = (perception.neighbors * perception.neighbor_mask[..., None]).sum(axis=(0, 1))
    return memory, steady(_ahead(perception.count) + seen)


def _reads_padding(
    memory: NoMemory, perception: Perception, inbox: Inbox, *, params: None
) -> tuple[NoMemory, Steering]:
    return memory, steady(_ahead(perception.count) + perception.neighbors.sum(axis=1))


def _first_neighbour(
    memory: NoMemory, perception: Perception, inbox: Inbox, *, params: None
) -> tuple[NoMemory, Steering]:
    return memory, steady(perception.neighbors[:, 0])  # none there when K = 0


def _restless(
    memory: NoMemory, perception: Perception, inbox: Inbox, *, params: None
) -> tuple[NoMemory, Steering]:
    return memory, steady(_ahead(perception.count) * np.random.default_rng().uniform())


@pytest.mark.parametrize(
    ("steer", "broken"),
    [
        (
            _school_mean,
            "a batch of 9 gives what each fish alone gives, memory included, over 3 decisions",
        ),
        (_reads_padding, "padding rows change nothing"),
        (_first_neighbour, "decides a batch where no fish sees anyone"),
        (_restless, "the same inputs give the same outputs"),
    ],
)
def test_each_rule_broken_is_found_with_what_went_wrong(steer: Any, broken: str) -> None:
    family = Behavior("mine", "a test's", steer, no_memory, lambda s: None, spawn_radius=0.5)
    found = check_decisions(FishParams(family, None))
    failed = dict(found.problems)
    assert broken in failed, found.problems
    if steer is _school_mean:
        assert failed[broken].startswith("at decision 1, fish 0 alone gives its fins [")
    if steer is _first_neighbour:
        assert failed[broken].startswith(
            "BehaviorError: the behaviour 'mine' deciding for 9 fish (0 neighbour rows each): "
            "its steer raised IndexError"
        )


def test_the_command_checks_a_behaviour_and_says_what_it_breaks(
    capsys: pytest.CaptureFixture[str],
) -> None:
    from fishswarm.behaviors.registry import register
    from fishswarm.cli import main

    assert main(["behaviors", "--check", "dispersion"]) == 0
    said = capsys.readouterr().out.splitlines()
    assert said[0] == "dispersion: checked on random perceptions (seeded)"
    assert said[1:] == [
        "  ok      decides a batch where no fish sees anyone",
        "  ok      a batch of 9 gives what each fish alone gives, memory included, over 3 "
        "decisions",
        "  ok      padding rows change nothing",
        "  ok      the same inputs give the same outputs",
        "dispersion keeps the rules",
    ]
    if "test-pads" not in BEHAVIORS:
        register(Behavior("test-pads", "reads padding", _reads_padding, no_memory, _none, 0.5))
    assert main(["behaviors", "--check", "test-pads"]) == 1
    said = capsys.readouterr().out.splitlines()
    assert "  FAILED  padding rows change nothing" in said
    assert said[-1] == "test-pads breaks 1 of the 4 rules"


def _none(settings: object) -> None:
    return None
