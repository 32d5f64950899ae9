"""Runs of a scenario through the whole actor system, as an experiment engine.

Router, world, channel, observer and the fish (in the launcher's process) over Zenoh on a
free loopback port, recorded to a temporary MCAP file that is read back: what
:func:`fishswarm.study.sweep.sweep_experiment` calls for ``--engine actors``.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np
import trio

from fishswarm.actors.launcher import LaunchSettings, launch_swarm
from fishswarm.actors.session import free_loopback_endpoint
from fishswarm.sim.scenario import Scenario
from fishswarm.study.recording import read_recording
from fishswarm.study.sweep import Run


def simulate_on_actors(scenario: Scenario) -> Run:
    """Run through the actor system, recording to a temporary MCAP file read back after."""
    endpoint = free_loopback_endpoint()
    with tempfile.TemporaryDirectory(prefix="fishswarm-experiment-") as folder:
        record = Path(folder) / "run.mcap"
        settings = LaunchSettings(scenario, listen=endpoint, record=record)
        try:
            result = trio.run(launch_swarm, settings)
        except BaseExceptionGroup as group:
            # Ctrl-C reaches the run's tasks and comes out of trio in a group: the sweep
            # (which keeps the runs done and writes them) knows a KeyboardInterrupt.
            if group.subgroup(KeyboardInterrupt) is not None:
                raise KeyboardInterrupt from None
            raise
        if result.summary["status"] != "finished":
            raise RuntimeError(
                f"run with seed {scenario.seed} ended {result.summary['status']} "
                f"(exit code {result.exit_code})"
            )
        snapshots = read_recording(record).snapshots
    t = np.array([s.time for s in snapshots])
    position = np.array([s.position for s in snapshots])
    seen = np.array([s.neighbors_seen for s in snapshots])
    effort = np.array(
        [np.zeros(s.ids.shape[0]) if s.effort is None else s.effort for s in snapshots]
    )
    return t, position, seen, effort
