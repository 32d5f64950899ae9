"""Make docs/images/learning_curves.png: spacing and speed over a trial, ideal fish against
the best replica, for every run of the table in docs/learning.md (each line a mean over the
20 fresh trials of that run's ``summary.json``), with the target's band around the ideal.

Run from the top of a checkout with the dev extras installed, after the runs:
``python docs/learning_pictures.py RUN_FOLDER ... [--out FILE]`` (each folder written by
``fishswarm learn --out``).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from fishswarm.learning.session import JUDGED_FROM, JUDGED_UNTIL, SPACING_TOLERANCE


def main() -> None:
    parser = argparse.ArgumentParser(description=" ".join(__doc__.split("\n\n")[0].split()))
    parser.add_argument("runs", type=Path, nargs="+", help="folders written by fishswarm learn")
    parser.add_argument(
        "--out",
        type=Path,
        default=Path("docs/images/learning_curves.png"),
        help="the picture to write (default: %(default)s)",
    )
    args = parser.parse_args()
    for run in args.runs:
        if not (run / "summary.json").is_file():
            parser.error(f"{run} holds no summary.json: give folders that fishswarm learn wrote")
    summaries = [json.loads((run / "summary.json").read_text()) for run in args.runs]
    behaviors = sorted({s["settings"]["behavior"] for s in summaries})
    figure, axes = plt.subplots(
        2, len(behaviors), figsize=(5.5 * len(behaviors), 6.5), squeeze=False, sharex=True
    )
    for column, behavior in enumerate(behaviors):
        runs = [s for s in summaries if s["settings"]["behavior"] == behavior]
        spacing_axes, speed_axes = axes[0, column], axes[1, column]
        ideal = np.array(runs[0]["ideal"]["spacing"])
        seconds = np.arange(len(ideal))
        spacing_axes.plot(seconds, ideal, color="black", linewidth=2.5, label="ideal fish")
        judged = (seconds >= JUDGED_FROM) & (seconds <= JUDGED_UNTIL)
        spacing_axes.fill_between(
            seconds[judged],
            ideal[judged] * (1 - SPACING_TOLERANCE),
            ideal[judged] * (1 + SPACING_TOLERANCE),
            color="0.85",
            label=f"target: within {100 * SPACING_TOLERANCE:.0f} %",
        )
        speed_axes.plot(seconds[1:], runs[0]["ideal"]["speed"], color="black", linewidth=2.5)
        for run in runs:
            seed = run["settings"]["seed"]
            met = "met" if run["target"]["met"] else "missed"
            line = spacing_axes.plot(
                seconds, run["replica"]["spacing"], label=f"replica, seed {seed} ({met})"
            )[0]
            speed_axes.plot(seconds[1:], run["replica"]["speed"], color=line.get_color())
        spacing_axes.set_title(f"{behavior}: mean neighbour distance")
        spacing_axes.set_ylabel("distance (units)")
        spacing_axes.legend(fontsize=8)
        speed_axes.set_title(f"{behavior}: mean speed")
        speed_axes.set_ylabel("speed (units/s)")
        speed_axes.set_xlabel("time in the trial (s)")
        speed_axes.set_yscale("symlog", linthresh=0.5)
    figure.tight_layout()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(args.out, dpi=110)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
