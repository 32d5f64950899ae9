"""Recordings of runs as MCAP files, and their export to NumPy and CSV.

A recording holds the run's scenario (metadata ``scenario``), every world snapshot exactly
as it went over the wire (topic ``snapshot``, msgpack), the metrics of each snapshot (topic
``metrics``, JSON), events such as fish joining or getting lost (topic ``events``, JSON), and
what the run looked like (topic ``scene``: Foxglove ``SceneUpdate`` messages, JSON, which
Foxglove and Lichtblick draw in 3-D). Because snapshots are stored as received, a recording
replays a run exactly.

Recordings survive a crash: messages go out in small chunks, each written to the file
(unbuffered) as soon as it is full, so a run killed outright leaves a file readable up to
its last whole chunk; reading such a file returns what it holds, marked incomplete.
"""

from __future__ import annotations

import csv
import fcntl
import io
import json
import logging
import os
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

import numpy as np
from mcap.reader import make_reader
from mcap.records import Channel, Message, Metadata
from mcap.stream_reader import CRCValidationError, StreamReader
from mcap.writer import Writer

from fishswarm.protocols.codec import MessageError, decode
from fishswarm.protocols.jsontext import json_text, number_or_nan
from fishswarm.protocols.messages import Snapshot
from fishswarm.study.scene import FRAME, SCENE_SCHEMA, scene_json_schema

CHUNK_SIZE = 32 * 1024
"""Bytes of messages per chunk: what a killed run can lose at most (three or four snapshots
of 25 fish with their metrics and scenes; from about 400 fish on, a snapshot's own chunk)."""
log = logging.getLogger(__name__)

SNAPSHOT_TOPIC = "snapshot"
METRICS_TOPIC = "metrics"
EVENTS_TOPIC = "events"
SCENE_TOPIC = "scene"


class RecordingError(ValueError):
    """A file is not a readable fishswarm recording."""


class Recorder:
    """Writes one run to an open MCAP stream; use :func:`open_recorder`."""

    def __init__(self, stream: IO[bytes] | _Flushing, scenario: dict[str, Any]) -> None:
        self._stream = stream
        self._writer = Writer(stream, chunk_size=CHUNK_SIZE)  # type: ignore[arg-type]
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
        scene_schema = self._writer.register_schema(
            name=SCENE_SCHEMA, encoding="jsonschema", data=json.dumps(scene_json_schema()).encode()
        )
        self._channels[SCENE_TOPIC] = self._writer.register_channel(
            SCENE_TOPIC, "json", scene_schema, metadata={"frame_id": FRAME}
        )
        self._sequence = 0

    def _add(self, topic: str, time: float, data: bytes) -> None:
        stamp = round(time * 1e9)
        self._writer.add_message(self._channels[topic], stamp, data, stamp, self._sequence)
        self._sequence += 1

    def scenario(self, settings: dict[str, Any]) -> None:
        """Record the settings of the run, in place of those the recording was opened with
        (an observer learns them from the world after it has begun to record)."""
        self._writer.add_metadata("scenario", {"json": json.dumps(settings)})

    @property
    def begun(self) -> bool:
        """Whether a snapshot was recorded: the file holds this run (before, it is left as
        it was)."""
        return not isinstance(self._stream, _Flushing) or self._stream.begun

    def snapshot(self, time: float, payload: bytes) -> None:
        """Record a snapshot payload as it came over the wire (the first begins the file)."""
        if isinstance(self._stream, _Flushing):
            self._stream.begin()
        self._add(SNAPSHOT_TOPIC, time, payload)

    def metrics(self, time: float, values: dict[str, Any]) -> None:
        """Record the metrics of one snapshot."""
        self._add(METRICS_TOPIC, time, json_text(values).encode())

    def scene(self, time: float, message: bytes) -> None:
        """Record what the swarm looked like (a Foxglove ``SceneUpdate``, JSON)."""
        self._add(SCENE_TOPIC, time, message)

    def event(self, time: float, values: dict[str, Any]) -> None:
        """Record an event (fish joined, fish lost, …)."""
        self._add(EVENTS_TOPIC, time, json_text(values).encode())

    def finish(self) -> None:
        """Write the summary sections and the footer."""
        self._writer.finish()


class _Flushing:
    """A file that hands every write to the operating system at once (the MCAP writer
    writes a chunk when it is full: it reaches the disk then, not when the run ends) —
    once :meth:`begin` is called; until then writes are held, and the file is left as it
    was (a run that never starts must not empty the recording it was given)."""

    def __init__(self, stream: IO[bytes]) -> None:
        self._stream = stream
        self._held: bytearray | None = bytearray()

    @property
    def begun(self) -> bool:
        """Whether the file is being written."""
        return self._held is None

    def begin(self) -> None:
        """Empty the file and write into it from now on, what was held first."""
        if self._held is None:
            return
        self._stream.seek(0)
        self._stream.truncate()
        self._stream.write(self._held)
        self._stream.flush()
        self._held = None

    def write(self, data: bytes) -> int:
        if self._held is not None:
            self._held += data
            return len(data)
        written = self._stream.write(data)
        self._stream.flush()
        return written

    def tell(self) -> int:
        return len(self._held) if self._held is not None else self._stream.tell()

    def flush(self) -> None:
        if self._held is None:
            self._stream.flush()


@contextmanager
def open_recorder(path: Path, scenario: dict[str, Any]) -> Iterator[Recorder]:
    """Record into ``path``, from the run's first snapshot on; the file is complete when
    the block ends. A run that records no snapshot (its fish never came up) leaves the file
    as it was, and makes none. The file is locked while it is written: another recorder of
    this machine refuses it.

    Raises:
        RecordingError: another process records into ``path`` (a run, a world or an
            observer given the same ``--record``); the file is left as it is.
    """
    path.parent.mkdir(parents=True, exist_ok=True)
    existed = path.exists()
    descriptor = os.open(path, os.O_RDWR | os.O_CREAT, 0o666)
    try:
        try:
            fcntl.flock(descriptor, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise RecordingError(
                f"{path} is being recorded into by another process (a run, world or observer "
                "given the same --record): give this one another file"
            ) from None
        except OSError as error:  # a file system without locks (some network mounts)
            log.warning("recording into %s unlocked: %s", path, error.strerror)
        # Emptied only once locked, and at the first snapshot (_Flushing.begin): a refused
        # recorder must not destroy the other's, nor a run that never starts its own.
        stream = os.fdopen(descriptor, "wb")
    except BaseException:
        os.close(descriptor)
        raise
    with stream:
        recorder = Recorder(_Flushing(stream), scenario)
        try:
            yield recorder
        finally:
            recorder.finish()
            if not recorder.begun and not existed:
                path.unlink(missing_ok=True)


@dataclass(frozen=True)
class Recording:
    """A recording read back.

    Attributes:
        scenario: the scenario's settings.
        snapshots: every snapshot, in tick order.
        metrics: the metrics of each snapshot.
        events: the events, in order.
        complete: False when the file ends early (the run was killed): it holds the run up
            to its last whole chunk.
    """

    scenario: dict[str, Any]
    snapshots: list[Snapshot]
    metrics: list[dict[str, Any]]
    events: list[dict[str, Any]]
    complete: bool = True

    def note(self, path: Path) -> str | None:
        """A warning for a recording cut short, saying how much it holds; None if complete."""
        if self.complete:
            return None
        last = f", up to tick {self.snapshots[-1].tick}" if self.snapshots else ""
        return (
            f"warning: {path} was cut short (the run that wrote it was killed?): read "
            f"{len(self.snapshots)} snapshots{last}"
        )

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
    """Read a recording; one cut short by a crash is read up to its last whole chunk and
    marked incomplete.

    Raises:
        RecordingError: the file is missing, empty, not MCAP, or holds invalid snapshots.
    """
    try:
        data = path.read_bytes()
    except OSError as error:
        raise RecordingError(f"cannot open recording {path}: {error.strerror}") from None
    if not data:
        raise RecordingError(
            f"{path} is empty (0 bytes): the run that wrote it ended before recording anything"
        )
    if not data.startswith(MCAP_MAGIC):
        raise RecordingError(f"{path} is not an MCAP recording (it does not start like one)")
    # A finished recording ends with the magic after its footer; one cut short does not.
    complete = len(data) > len(MCAP_MAGIC) and data.endswith(MCAP_MAGIC)
    if not complete:
        contents = _read_stream(path, data)
    else:
        contents = _Contents()
        try:
            # Checksums checked: a chunk damaged on disk is said so, not read past silently.
            reader = make_reader(io.BytesIO(data), validate_crcs=True)
            for metadata in reader.iter_metadata():
                contents.metadata(metadata.name, metadata.metadata)
            for _, channel, message in reader.iter_messages(log_time_order=False):
                contents.message(path, channel.topic, message.data)
        except RecordingError:
            raise
        except CRCValidationError:
            raise RecordingError(_damaged(path)) from None
        except Exception as error:
            raise RecordingError(f"{path} is not a readable MCAP recording: {error}") from None
    contents.snapshots.sort(key=lambda s: s.tick)
    if not complete:
        # Each snapshot is followed by its metrics; a cut may fall between the two (in a
        # large swarm a snapshot fills a chunk of its own, and its metrics are in the next).
        whole = min(len(contents.snapshots), len(contents.metrics))
        del contents.snapshots[whole:], contents.metrics[whole:]
    return Recording(
        contents.scenario, contents.snapshots, contents.metrics, contents.events, complete
    )


MCAP_MAGIC = b"\x89MCAP0\r\n"


def _damaged(path: Path, what: str = "fails its checksum") -> str:
    """What to say of a recording whose chunk fails its checksum (or ``what`` else)."""
    return (
        f"{path} is damaged: a chunk of it {what}, so the file was changed after it was "
        "written; it is not read (a recording cut short by a crash is)"
    )


@dataclass
class _Contents:
    """What has been read of a recording so far."""

    scenario: dict[str, Any] = field(default_factory=dict)
    snapshots: list[Snapshot] = field(default_factory=list)
    metrics: list[dict[str, Any]] = field(default_factory=list)
    events: list[dict[str, Any]] = field(default_factory=list)

    def metadata(self, name: str, values: dict[str, str]) -> None:
        if name == "scenario":
            self.scenario = json.loads(values["json"])

    def message(self, path: Path, topic: str, data: bytes) -> None:
        if topic == SNAPSHOT_TOPIC:
            try:
                self.snapshots.append(decode(data, Snapshot))
            except MessageError as error:
                raise RecordingError(f"{path} holds an invalid snapshot: {error}") from None
        elif topic == METRICS_TOPIC:
            values = json.loads(data)
            self.metrics.append({name: number_or_nan(value) for name, value in values.items()})
        elif topic == EVENTS_TOPIC:
            self.events.append(json.loads(data))


def _read_stream(path: Path, data: bytes) -> _Contents:
    """The records of a file without footer, in order, up to the first that is cut off."""
    contents = _Contents()
    topics: dict[int, str] = {}
    stream = io.BytesIO(data)
    try:
        for record in StreamReader(stream, validate_crcs=True).records:
            if isinstance(record, Channel):
                topics[record.id] = record.topic
            elif isinstance(record, Message) and record.channel_id in topics:
                contents.message(path, topics[record.channel_id], record.data)
            elif isinstance(record, Metadata):
                contents.metadata(record.name, record.metadata)
    except RecordingError:
        raise
    except CRCValidationError:
        raise RecordingError(_damaged(path)) from None
    except Exception as error:
        # A cut leaves its last record short: the reader fails at the end of the file. A
        # record that fails before the end was there whole, and is damaged (a chunk whose
        # compressed bytes were changed fails to decompress before its checksum is seen).
        if stream.tell() < len(data):
            raise RecordingError(
                _damaged(path, f"cannot be read ({type(error).__name__}: {error})")
            ) from None
    return contents


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
