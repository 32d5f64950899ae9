"""Command-line options several benchmarks share: the swarm sizes and worker counts to time."""

from __future__ import annotations

import argparse


def add_sizes(
    parser: argparse.ArgumentParser, *, fish: list[int], procs: list[int] | None = None
) -> None:
    """Add ``--fish`` (swarm sizes, default ``fish``) and, given ``procs``, ``--procs``
    (worker processes for each size)."""
    parser.add_argument(
        "--fish",
        type=int,
        nargs="+",
        default=fish,
        help=f"swarm sizes to time (default: {' '.join(map(str, fish))})",
    )
    if procs is not None:
        parser.add_argument(
            "--procs",
            type=int,
            nargs="+",
            default=procs,
            help="worker processes for each size, 0 for the fish in the launcher's process "
            f"(default: {' '.join(map(str, procs))})",
        )
