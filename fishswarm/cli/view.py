"""``fishswarm view``: a swarm in 3-D in the browser, attached live to a running swarm (as
an observer) or replaying a recording."""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
from pathlib import Path

import trio

from fishswarm.actors.control import wait_for_scenario
from fishswarm.actors.observer import Observer
from fishswarm.actors.security import observer_subject
from fishswarm.actors.session import open_session
from fishswarm.actors.zenoh_bus import ZenohBus
from fishswarm.bluebot.parameters import Tank
from fishswarm.cli.common import UserError, client_settings, read_recording_for, refuse_unused
from fishswarm.cli.swarm import (
    _run_trio,
    refuse_observer_name,
    say_waiting_for_world,
    view_settings,
    wait_for_ctrl_c,
    wait_for_run_end,
)
from fishswarm.protocols.keys import KeySpace
from fishswarm.sim.scenario import ConfigError, Scenario
from fishswarm.study.live_view import LiveView, open_live_view
from fishswarm.study.metrics import FormationTargets
from fishswarm.study.recording import RecordingError
from fishswarm.study.scene import Stage, scene_of, stage_of
from fishswarm.study.view_settings import ViewError, ViewSettings

NOT_METRICS = ("tick", "time", "fish")
"""Entries of a recorded metrics record that are not metrics."""


def view(args: argparse.Namespace, scenario: Scenario | None) -> int:
    """``fishswarm view``: serve the view until Ctrl-C."""
    if args.recording is not None:
        live = {"connect": "--connect", "secure": "--secure", "name": "--name", "swarm": "--swarm"}
        refuse_unused(
            args,
            {name: flag for name, flag in live.items() if name not in args.defaulted_endpoints},
            applies="when following a live swarm (no RECORDING)",
            fix="a recording is replayed as it was recorded; leave {it} out",
        )
    refuse_observer_name(args)
    args.swarm = args.swarm or "default"
    settings = dataclasses.replace(view_settings(args), open_browser=args.open)
    try:
        if args.recording is not None:
            _replay(args.recording, settings)
        else:
            _attach(args, settings)
    except (ViewError, RecordingError) as error:
        raise UserError(str(error)) from None
    except KeyboardInterrupt:
        print("fishswarm view: closed", file=sys.stderr)
    return 0


def _announce(view: LiveView, what: str) -> None:
    print(f"fishswarm view: {what}", file=sys.stderr)
    print(f"open {view.settings.page_url} in a browser; Ctrl-C to stop", file=sys.stderr)
    sys.stderr.flush()


def _replay(path: Path, settings: ViewSettings) -> None:
    recording = read_recording_for(path, at_least=1, purpose="show")
    try:
        ran: Scenario | None = Scenario.as_recorded(recording.scenario, source=str(path))
    except ConfigError:  # an observer's whose world never told it what ran
        ran = None
    targets = None if ran is None else FormationTargets.of(ran)
    stage = stage_of(ran) if ran is not None else Stage(Tank().size)
    with open_live_view(settings, name=path.stem) as view:
        view.show_stage(stage)
        for snapshot, record in zip(recording.snapshots, recording.metrics, strict=False):
            metrics = {k: v for k, v in record.items() if k not in NOT_METRICS}
            target = None if targets is None else targets.told(snapshot.formation, snapshot.time)
            view.show(scene_of(snapshot, target), metrics)
        first, last = recording.snapshots[0].time, recording.snapshots[-1].time
        note = "" if recording.complete else " (cut short: the run did not finish)"
        _announce(
            view,
            f"replaying {path}: {view.scenes} snapshots, t = {first:g}–{last:g} s{note}",
        )
        wait_for_ctrl_c()


class _Runs:
    """The runs a live view follows, one recording each: the first from the start, each
    later one from its first snapshot on (the observer's ``on_new_run``)."""

    def __init__(self, view: LiveView, swarm: str) -> None:
        self.view = view
        self.swarm = swarm
        self.count = 1
        self.scenes: dict[int, int] = {}
        """Snapshots shown of each run that has given way to a later one."""
        self._begun = trio.Event()
        self._send, self.begun = trio.open_memory_channel[int](math.inf)
        """The number of each later run, as it begins."""

    def begin(self, run: int) -> None:
        """A later run's snapshots begin: draw them into a recording of their own."""
        self.scenes[self.count] = self.view.scenes
        self.count += 1
        self.view.start_run(f"swarm {self.swarm}, run {self.count}")
        self._send.send_nowait(self.count)
        self._begun.set()
        self._begun = trio.Event()

    async def wait_for_run(self, after: int) -> None:
        """Wait until a run later than the ``after``-th has begun."""
        while self.count <= after:
            await self._begun.wait()


async def _goes_on(observer: Observer, runs: _Runs, watched: int) -> bool:
    """After the world of the ``watched``-th run left unfinished, wait until it is back
    (True) or a later run begins (False)."""
    back = False
    async with trio.open_nursery() as nursery:

        async def world_back() -> None:
            nonlocal back
            await observer.wait_for_world_back()
            back = True
            nursery.cancel_scope.cancel()

        async def next_run() -> None:
            await runs.wait_for_run(after=watched)
            nursery.cancel_scope.cancel()

        nursery.start_soon(world_back)
        nursery.start_soon(next_run)
    return back and runs.count == watched


def _attach(args: argparse.Namespace, settings: ViewSettings) -> None:
    keys = KeySpace(args.swarm)

    def say(what: str) -> None:
        print(f"fishswarm view: {what}", file=sys.stderr)

    async def main() -> None:
        with open_live_view(settings, name=f"swarm {args.swarm}, run 1") as view:
            # The study's tank until the world says which (a world may be slow to answer, or
            # be gone before it can: the view shows what it sees meanwhile).
            view.show_stage(Stage(Tank().size))
            runs = _Runs(view, args.swarm)
            async with (
                open_session(
                    client_settings(args, observer_subject(args.name), swarm=args.swarm)
                ) as session,
                trio.open_nursery() as nursery,
            ):
                observer = Observer(
                    keys, on_scene=view.show, observer_id="view", on_new_run=runs.begin
                )
                await nursery.start(observer.run, ZenohBus(session))
                _announce(view, f"following swarm {args.swarm!r} on {args.connect}")

                async def learn_the_run(number: int) -> None:
                    """Ask the world what its run is, until it answers or the run ends (a
                    short run in lockstep may end before the view asks)."""
                    ran = None
                    async with trio.open_nursery() as asking:

                        async def until_the_run_ends() -> None:
                            await observer.wait_for_world_end(settle=0.0)
                            asking.cancel_scope.cancel()

                        asking.start_soon(until_the_run_ends)
                        try:
                            ran = await wait_for_scenario(
                                session,
                                keys,
                                on_waiting=(
                                    lambda: say_waiting_for_world("view", keys, args.connect)
                                )
                                if number == 1
                                else None,
                            )
                        except ConfigError as error:
                            # A behaviour not installed here, say: the fish are shown all
                            # the same, in the study's tank.
                            without = f"the view shows run {number} without its settings"
                            say(f"warning: {error}; {without}")
                            return
                        finally:
                            asking.cancel_scope.cancel()
                    if runs.count != number:
                        return  # a later run began meanwhile: it learns its own
                    if ran is None:
                        say(f"run {number} ended before its world told its settings")
                        return
                    observer.measure_as(ran)
                    view.show_stage(stage_of(ran))
                    say(f"the world runs {ran.fish} fish, {ran.behavior}, {ran.duration:g} s")

                async def learn_each_run() -> None:
                    await learn_the_run(1)
                    async for number in runs.begun:
                        await learn_the_run(number)

                nursery.start_soon(learn_each_run)
                watched = 1
                while True:
                    why = await wait_for_run_end(observer, session, args.connect)
                    shown = runs.scenes.get(watched, view.scenes)
                    if why is not None:
                        say(
                            f"{why} before the run ended ({shown} snapshots shown; its world "
                            "never said the run was over): the view stays up until Ctrl-C, and "
                            "shows what comes when the router and the world are back"
                        )
                        if await _goes_on(observer, runs, watched):
                            say(
                                f"the world of run {watched} is back (the last snapshot shown "
                                f"was of tick {observer.last_tick}): the view goes on with it"
                            )
                            continue
                    else:
                        say(
                            f"the run has ended ({shown} snapshots shown); the view stays up "
                            "until Ctrl-C, and shows the swarm's next run"
                        )
                    await runs.wait_for_run(after=watched)
                    watched = runs.count
                    say(
                        f"run {watched} of swarm {args.swarm!r} begins: shown as a new "
                        "recording (the earlier runs stay listed on the page)"
                    )

    _run_trio(main)
