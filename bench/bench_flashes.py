"""Benchmark: what telling flashers apart costs a robot's sensing each control period.

A robot whose fish flags runs the LED pipeline on two images per camera each period (frames 0
and 2 of a burst, half a flash period apart) and merges the two sets of neighbours
(:func:`fishswarm.bluebot.flashes.merge_frames`); one that does not runs it on one image per
camera. This times both on the same rendered scenes — 1 to 10 neighbours 0.2–3 m away, half
of them flashing, each from its own phase — with rendering left out (a robot's camera gives
the images), and reports the medians and their ratio. The ratio carries over to a Pi better
than the times do: a Pi Zero runs the same numpy, only slower.

Usage:
    python bench/bench_flashes.py [--scenes 200]
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from fishswarm.bluebot.fisheye import Fisheye
from fishswarm.bluebot.flashes import FRAME_GAP, lit_at, merge_frames
from fishswarm.bluebot.leds import LedVision, perceive_leds
from fishswarm.bluebot.parameters import BlueBot, Tank
from fishswarm.sim.camera import Optics, render_views


def scene(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A viewer (row 0) and 1–10 neighbours 0.2–3 m from it in the study's tank; which of
    the neighbours flash."""
    size = np.array(Tank().size)
    viewer = rng.uniform(0.0, 1.0, 3) * size
    viewer[2] = max(viewer[2], 0.06)
    positions = [viewer]
    count = int(rng.integers(1, 11))
    while len(positions) < count + 1:
        other = rng.uniform(0.0, 1.0, 3) * size
        if other[2] >= 0.06 and 0.2 <= np.linalg.norm(other - viewer) <= 3.0:
            positions.append(other)
    flashes = rng.random(count + 1) < 0.5
    flashes[0] = False
    return np.array(positions), rng.uniform(-np.pi, np.pi, count + 1), flashes


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", type=int, default=200, help="rendered scenes (default 200)")
    args = parser.parse_args()
    rng = np.random.default_rng(7)
    fisheye, optics, robot, vision = Fisheye(), Optics(), BlueBot(), LedVision()
    one_frame: list[float] = []
    two_frames: list[float] = []
    for _ in range(args.scenes):
        position, yaw, flashes = scene(rng)
        phase = rng.random(flashes.size)
        start = float(rng.uniform(0.0, 10.0))
        frames = [
            render_views(
                position,
                yaw,
                0,
                fisheye=fisheye,
                optics=optics,
                robot=robot,
                rng=rng,
                lit=~flashes | lit_at(at, phase),
            )
            for at in (start, start + FRAME_GAP)
        ]
        depth = float(position[0, 2])
        began = time.perf_counter()
        perceive_leds(frames[0], depth=depth, fisheye=fisheye, vision=vision)
        one_frame.append(time.perf_counter() - began)
        began = time.perf_counter()
        first, second = (
            perceive_leds(images, depth=depth, fisheye=fisheye, vision=vision) for images in frames
        )
        merge_frames(first, second)
        two_frames.append(time.perf_counter() - began)
    single, double = statistics.median(one_frame), statistics.median(two_frames)
    print(f"{args.scenes} scenes, 1-10 neighbours, half of them flashing (rendering left out)")
    print(f"one image per camera:              {single * 1e3:6.2f} ms a period (median)")
    print(f"two per camera, merged (flagging): {double * 1e3:6.2f} ms a period (median)")
    print(f"ratio: {double / single:.2f}")


if __name__ == "__main__":
    main()
