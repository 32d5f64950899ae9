"""Benchmark: seeing through rendered camera images against geometric vision.

For swarms of 10 and 25 fish placed at random in the study's tank, times, in one run,
(a) the geometric vision model for the whole swarm (``perceive``), (b) rendering both camera
images of every fish, and (c) the LED pipeline on those images, and reports (b) and (c) per
fish and as multiples of (a); then whole runs of the study's dispersion set-up (15 s at
1 Hz) in the batch engine with ``vision_model = "camera"`` against the same runs with
geometric vision (what ``fishswarm run --vision camera`` costs the world). With
``--picture PATH`` it also draws one fish's two images
with the blobs the pipeline found.

Usage:
    python bench/bench_camera.py [--repeats 5] [--picture docs/images/camera_views.png]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from fishswarm.bluebot.blobs import find_blobs
from fishswarm.bluebot.fisheye import Fisheye
from fishswarm.bluebot.leds import LedVision, perceive_leds
from fishswarm.bluebot.parameters import BlueBot, Tank
from fishswarm.bluebot.ports import CAMERA_SIDES
from fishswarm.bluebot.vision import Vision, perceive
from fishswarm.sim.camera import Optics, render_views
from fishswarm.sim.engine import simulate_batch
from fishswarm.sim.scenario import Scenario


def swarm(count: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    size = np.array(Tank().size)
    position = rng.uniform(0.0, 1.0, (count, 3)) * size
    position[:, 2] = np.maximum(position[:, 2], 0.06)
    return position, rng.uniform(-np.pi, np.pi, count)


def measure(count: int, repeats: int) -> dict[str, float]:
    rng = np.random.default_rng(count)
    fisheye, optics, robot, led_vision = Fisheye(), Optics(), BlueBot(), LedVision()
    geometric = render = pipeline = 0.0
    for _ in range(repeats):
        position, yaw = swarm(count, rng)
        start = time.perf_counter()
        perceive(position, yaw, vision=Vision())
        geometric += time.perf_counter() - start
        for fish in range(count):
            start = time.perf_counter()
            images = render_views(
                position, yaw, fish, fisheye=fisheye, optics=optics, robot=robot, rng=rng
            )
            middle = time.perf_counter()
            perceive_leds(images, depth=position[fish, 2], fisheye=fisheye, vision=led_vision)
            render += middle - start
            pipeline += time.perf_counter() - middle
    ticks = repeats
    return {
        "geometric_ms_per_tick": 1e3 * geometric / ticks,
        "render_ms_per_fish": 1e3 * render / (ticks * count),
        "pipeline_ms_per_fish": 1e3 * pipeline / (ticks * count),
        "camera_over_geometric": (render + pipeline) / geometric,
    }


def measure_runs(count: int) -> dict[str, float]:
    """Seconds for one dispersion run of ``count`` fish with each vision model, and the ratio."""
    seconds = {}
    for model in ("geometric", "camera"):
        scenario = Scenario(fish=count, behavior="dispersion", seed=1, vision_model=model)
        start = time.perf_counter()
        simulate_batch(scenario)
        seconds[model] = time.perf_counter() - start
    return {
        "geometric_run_s": seconds["geometric"],
        "camera_run_s": seconds["camera"],
        "camera_run_over_geometric": seconds["camera"] / seconds["geometric"],
    }


def picture(path: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rng = np.random.default_rng(3)
    position, yaw = swarm(10, rng)
    position[0] = (0.9, 0.9, 0.45)
    images = render_views(
        position, yaw, 0, fisheye=Fisheye(), optics=Optics(), robot=BlueBot(), rng=rng
    )
    figure, axes = plt.subplots(1, 2, figsize=(10, 4))
    for axis, side in zip(axes, CAMERA_SIDES, strict=True):
        image = images[side]
        blobs = find_blobs(image[:, :, 2], threshold=40, saddle_ratio=0.7)
        axis.imshow(np.clip(image.astype(np.float64) * 3, 0, 255).astype(np.uint8))
        axis.scatter(
            blobs.centroids[:, 1],
            blobs.centroids[:, 0],
            s=60,
            facecolors="none",
            edgecolors="orange",
            linewidths=0.8,
        )
        axis.set_title(f"{side} camera (256×192, brightened ×3; circles: blobs)")
        axis.set_axis_off()
    figure.tight_layout()
    figure.savefig(path, dpi=110)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5, help="swarms timed per size")
    parser.add_argument("--picture", help="also draw one fish's two images to this PNG")
    args = parser.parse_args()
    for count in (10, 25):
        result = measure(count, args.repeats) | measure_runs(count)
        print(f"{count} fish: " + ", ".join(f"{k} {v:.3g}" for k, v in result.items()))
    if args.picture:
        picture(args.picture)
        print(f"wrote {args.picture}")


if __name__ == "__main__":
    main()
