"""Progress lines: one updating line on a terminal, one line per report elsewhere."""

from __future__ import annotations

import io

from fishswarm.actors.observer import Progress
from fishswarm.cli.swarm import progress_printer
from fishswarm.study.progress import ProgressLine

METRICS = {
    "centroid_distance": 0.5,
    "pairwise_distance": 0.7,
    "nearest_neighbor_distance": 0.2,
    "neighbors_seen": 3.0,
}


class Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_an_observer_that_does_not_know_the_end_shows_no_total_and_closes_its_line() -> None:
    terminal = Terminal()
    line = ProgressLine(terminal)
    show = progress_printer(None, line)
    for tick in range(3):
        show(Progress(tick, 0.1 * tick, 5, METRICS))
    written = terminal.getvalue()
    assert "/" not in written and "[" not in written  # neither "tick 2/0" nor a bar
    assert written.count("\r") == 3 and "\n" not in written  # one line, rewritten
    assert written.endswith("tick 2  t=    0.2 s  fish 5  centroid 0.500 m  pairwise 0.700 m  "
                            "nearest 0.200 m  seen 3.0")  # fmt: skip
    line.close()
    line.close()  # once is enough
    assert terminal.getvalue() == written + "\n"


def test_elsewhere_an_open_ended_observer_prints_every_tenth_snapshot() -> None:
    log = io.StringIO()
    show = progress_printer(None, ProgressLine(log))
    for tick in range(25):
        show(Progress(tick, float(tick), 5, METRICS))
    assert [entry.split()[1] for entry in log.getvalue().splitlines()] == ["0", "10", "20"]


def test_a_run_of_known_length_ends_its_line_at_the_last_tick() -> None:
    terminal = Terminal()
    line = ProgressLine(terminal)
    show = progress_printer(4, line)
    for tick in range(5):
        show(Progress(tick, float(tick), 5, METRICS))
    assert terminal.getvalue().endswith("seen 3.0\n")
    assert "tick 4/4" in terminal.getvalue() and "[####################]" in terminal.getvalue()
    line.close()  # nothing left open
    assert terminal.getvalue().endswith("seen 3.0\n")


def test_an_observer_that_came_after_its_last_tick_says_so_instead_of_tick_5_of_1() -> None:
    terminal = Terminal()
    line = ProgressLine(terminal)
    progress_printer(1, line)(Progress(5, 0.5, 5, METRICS))
    assert terminal.getvalue() == (
        "\rtick 5 (after the last tick asked for, 1)  t=    0.5 s  fish 5  centroid 0.500 m  "
        "pairwise 0.700 m  nearest 0.200 m  seen 3.0\n"
    )
