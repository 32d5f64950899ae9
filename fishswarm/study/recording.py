"""Recordings of runs as MCAP files, and their export to NumPy and CSV.

A recording holds the run's scenario (metadata ``scenario``), every world snapshot exactly
as it went over the wire (topic ``snapshot``, msgpack), the metrics of each snapshot (topic
``metrics``, JSON) and events such as fish joining or getting lost (topic ``events``, JSON).
Because snapshots are stored as received, a recording replays a run exactly.
"""

from __future__ import annotations

import csv
import json
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

import numpy as np
from mcap.reader import make_reader
from mcap.writer import Writer

from fishswarm.protocols.codec import MessageError, decode
from fishswarm.protocols.messages import Snapshot

SNAPSHOT_TOPIC = "snapshot"
METRICS_TOPIC = "metrics"
EVENTS_TOPIC = "events"


class RecordingError(ValueError):
    """A file is not a readable fishswarm recording."""


class Recorder:
    """Writes one run to an open MCAP stream; use :func:`open_recorder`."""

    def __init__(self, stream: IO[bytes], scenario: dict[str, Any]) -> None:
        self._writer = Writer(stream)
        self._writer.start(profile="fishswarm", library="fishswarm")
        self._writer.add_metadata("scenario", {"json": json.dumps(scenario)})
        snapshot_schema = self._writer.register_schema(
            name="fishswarm.Snapshot", encoding="", data=b""
        )
        json_schema = self._writer.register_schema(
            name="fishswarm.Record", encoding="jsonschema", data=b'{"type": "object"}'
        )
        self._channels = {
            SNAPSHOT_TOPIC: self._writer.register_channel(
                SNAPSHOT_TOPIC, "msgpack", snapshot_schema
            ),
            METRICS_TOPIC: self._writer.register_channel(METRICS_TOPIC, "json", json_schema),
            EVENTS_TOPIC: self._writer.register_channel(EVENTS_TOPIC, "json", json_schema),
        }
        self._sequence = 0

    def _add(self, topic: str, time: float, data: bytes) -> None:
        stamp = round(time * 1e9)
        self._writer.add_message(self._channels[topic], stamp, data, stamp, self._sequence)
        self._sequence += 1

    def snapshot(self, time: float, payload: bytes) -> None:
        """Record a snapshot payload as it came over the wire."""
        self._add(SNAPSHOT_TOPIC, time, payload)

    def metrics(self, time: float, values: dict[str, Any]) -> None:
        """Record the metrics of one snapshot."""
        self._add(METRICS_TOPIC, time, json.dumps(values).encode())

    def event(self, time: float, values: dict[str, Any]) -> None:
        """Record an event (fish joined, fish lost, …)."""
        self._add(EVENTS_TOPIC, time, json.dumps(values).encode())

    def finish(self) -> None:
        """Write the summary sections and the footer."""
        self._writer.finish()


@contextmanager
def open_recorder(path: Path, scenario: dict[str, Any]) -> Iterator[Recorder]:
    """Create ``path`` and record into it; the file is complete when the block ends."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("wb") as stream:
        recorder = Recorder(stream, scenario)
        try:
            yield recorder
        finally:
            recorder.finish()


@dataclass(frozen=True)
class Recording:
    """A recording read back.

    Attributes:
        scenario: the scenario's settings.
        snapshots: every snapshot, in tick order.
        metrics: the metrics of each snapshot.
        events: the events, in order.
    """

    scenario: dict[str, Any]
    snapshots: list[Snapshot]
    metrics: list[dict[str, Any]]
    events: list[dict[str, Any]]

    def arrays(self) -> dict[str, np.ndarray]:
        """The run as arrays, SI units: ``t`` (T,), ``pos`` (T, N, 3), ``vel`` (T, N, 3),
        ``yaw`` (T, N), ``ids`` (N,). A fish absent at a tick (not yet joined, or lost) has
        NaN there."""
        ids = (
            np.unique(np.concatenate([s.ids for s in self.snapshots]))
            if self.snapshots
            else (np.zeros(0, dtype=np.int64))
        )
        column = {int(i): n for n, i in enumerate(ids.tolist())}
        count, steps = ids.size, len(self.snapshots)
        pos = np.full((steps, count, 3), np.nan)
        vel = np.full((steps, count, 3), np.nan)
        yaw = np.full((steps, count), np.nan)
        for row, snapshot in enumerate(self.snapshots):
            columns = [column[int(i)] for i in snapshot.ids.tolist()]
            pos[row, columns] = snapshot.position
            vel[row, columns] = snapshot.velocity
            yaw[row, columns] = snapshot.yaw
        t = np.array([s.time for s in self.snapshots], dtype=np.float64)
        return {"t": t, "pos": pos, "vel": vel, "yaw": yaw, "ids": ids.astype(np.int64)}


def read_recording(path: Path) -> Recording:
    """Read a recording.

    Raises:
        RecordingError: the file is missing, not MCAP, or holds invalid snapshots.
    """
    try:
        stream = path.open("rb")
    except OSError as error:
        raise RecordingError(f"cannot open recording {path}: {error.strerror}") from None
    with stream:
        try:
            reader = make_reader(stream)
            scenario: dict[str, Any] = {}
            for metadata in reader.iter_metadata():
                if metadata.name == "scenario":
                    scenario = json.loads(metadata.metadata["json"])
            snapshots, metrics, events = [], [], []
            for _, channel, message in reader.iter_messages(log_time_order=False):
                if channel.topic == SNAPSHOT_TOPIC:
                    snapshots.append(decode(message.data, Snapshot))
                elif channel.topic == METRICS_TOPIC:
                    metrics.append(json.loads(message.data))
                elif channel.topic == EVENTS_TOPIC:
                    events.append(json.loads(message.data))
        except MessageError as error:
            raise RecordingError(f"{path} holds an invalid snapshot: {error}") from None
        except Exception as error:
            raise RecordingError(f"{path} is not a readable MCAP recording: {error}") from None
    snapshots.sort(key=lambda s: s.tick)
    return Recording(scenario, snapshots, metrics, events)


def export_npz(recording: Recording, out: Path) -> None:
    """Write the arrays of :meth:`Recording.arrays` to a ``.npz`` file."""
    out.parent.mkdir(parents=True, exist_ok=True)
    arrays = recording.arrays()
    np.savez_compressed(
        out,
        t=arrays["t"],
        pos=arrays["pos"],
        vel=arrays["vel"],
        yaw=arrays["yaw"],
        ids=arrays["ids"],
    )


def export_csv(recording: Recording, out: Path) -> None:
    """Write one row per (tick, fish): t, id, x, y, z, vx, vy, vz, yaw, neighbors_seen."""
    out.parent.mkdir(parents=True, exist_ok=True)
    with out.open("w", newline="", encoding="utf-8") as stream:
        writer = csv.writer(stream)
        writer.writerow(
            ["tick", "t", "id", "x", "y", "z", "vx", "vy", "vz", "yaw", "neighbors_seen"]
        )
        for s in recording.snapshots:
            for n, fish_id in enumerate(s.ids.tolist()):
                writer.writerow(
                    [
                        s.tick,
                        repr(s.time),
                        fish_id,
                        *(repr(float(v)) for v in s.position[n]),
                        *(repr(float(v)) for v in s.velocity[n]),
                        repr(float(s.yaw[n])),
                        int(s.neighbors_seen[n]),
                    ]
                )
