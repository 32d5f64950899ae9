"""Recordings: what is written reads back exactly; absent fish become NaN on export."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import pytest
from mcap.records import Chunk
from mcap.stream_reader import StreamReader

from fishswarm.protocols.codec import encode
from fishswarm.protocols.messages import Snapshot
from fishswarm.study.recording import RecordingError, export_npz, open_recorder, read_recording


def _snapshot(tick: int, ids: list[int]) -> Snapshot:
    count = len(ids)
    position = np.arange(count * 3, dtype=float).reshape(count, 3) + tick
    return Snapshot(
        tick,
        float(tick),
        np.array(ids),
        position,
        -position,
        np.full(count, 0.1 * tick),
        np.ones(count, dtype=np.int64),
        np.zeros(count, dtype=np.int64),
    )


def test_a_recording_in_progress_is_not_taken_by_a_second_recorder(tmp_path: Path) -> None:
    # Two recorders given one file (an observer's --record, the run's own): the second is
    # refused before it empties the file, and the first records on, whole.
    path = tmp_path / "r.mcap"
    with open_recorder(path, {"fish": 2}) as recorder:
        recorder.snapshot(0.0, encode(_snapshot(0, [0, 1])))
        refused = "is being recorded into by another process"
        with pytest.raises(RecordingError, match=refused), open_recorder(path, {}):
            pass  # pragma: no cover
        recorder.snapshot(1.0, encode(_snapshot(1, [0, 1])))
    recording = read_recording(path)
    assert recording.complete and recording.scenario == {"fish": 2}
    assert [s.tick for s in recording.snapshots] == [0, 1]
    # Finished, the file is free: a new recording replaces it, from its first snapshot.
    with open_recorder(path, {"fish": 3}) as recorder:
        recorder.snapshot(0.0, encode(_snapshot(0, [0, 1, 2])))
    assert read_recording(path).scenario == {"fish": 3}
    assert [s.ids.size for s in read_recording(path).snapshots] == [3]


def test_a_run_that_records_no_snapshot_leaves_the_file_as_it_was(tmp_path: Path) -> None:
    # A world given --record whose fish never came up: the earlier recording stays whole,
    # and where there was none, none is made.
    path = tmp_path / "kept.mcap"
    with open_recorder(path, {"fish": 2}) as recorder:
        recorder.snapshot(0.0, encode(_snapshot(0, [0, 1])))
    kept = path.read_bytes()
    with open_recorder(path, {"fish": 10}) as recorder:
        recorder.event(0.0, {"event": "waiting"})
        assert path.read_bytes() == kept  # while it waits, too
    assert not recorder.begun and path.read_bytes() == kept
    fresh = tmp_path / "fresh.mcap"
    with open_recorder(fresh, {"fish": 10}):
        pass
    assert not fresh.exists()


def test_the_scenario_recorded_last_is_the_recordings(tmp_path: Path) -> None:
    # An observer learns what runs after it has begun to record.
    path = tmp_path / "r.mcap"
    with open_recorder(path, {"observed": True}) as recorder:
        recorder.snapshot(0.0, encode(_snapshot(0, [0, 1])))
        recorder.scenario({"fish": 2, "behavior": "formation"})
        recorder.snapshot(1.0, encode(_snapshot(1, [0, 1])))
    assert read_recording(path).scenario == {"fish": 2, "behavior": "formation"}
    # Cut short (the observer killed), it says so too.
    whole = path.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(whole[: len(whole) - 200])
    assert read_recording(cut).scenario == {"fish": 2, "behavior": "formation"}


def test_round_trip_with_a_fish_that_joins_and_one_that_leaves(tmp_path: Path) -> None:
    path = tmp_path / "r.mcap"
    snapshots = [_snapshot(0, [0, 1]), _snapshot(1, [0, 1, 5]), _snapshot(2, [1, 5])]
    with open_recorder(path, {"fish": 2}) as recorder:
        for snapshot in snapshots:
            recorder.snapshot(snapshot.time, encode(snapshot))
            recorder.metrics(snapshot.time, {"tick": snapshot.tick})
        recorder.event(1.0, {"event": "joined", "id": "5"})
    recording = read_recording(path)
    assert recording.scenario == {"fish": 2}
    assert recording.snapshots == snapshots
    assert [m["tick"] for m in recording.metrics] == [0, 1, 2]
    assert recording.events == [{"event": "joined", "id": "5"}]
    arrays = recording.arrays()
    assert arrays["ids"].tolist() == [0, 1, 5]
    assert np.isnan(arrays["pos"][0, 2]).all()
    assert np.isnan(arrays["pos"][2, 0]).all()
    np.testing.assert_array_equal(arrays["pos"][1], snapshots[1].position)
    np.testing.assert_array_equal(arrays["vel"][2, 1:], snapshots[2].velocity)
    export_npz(recording, tmp_path / "out.npz")
    assert np.load(tmp_path / "out.npz")["t"].tolist() == [0.0, 1.0, 2.0]


def test_missing_file_is_a_clear_error(tmp_path: Path) -> None:
    with pytest.raises(RecordingError, match="cannot open recording"):
        read_recording(tmp_path / "none.mcap")


def test_a_recording_cut_anywhere_reads_up_to_its_last_whole_chunk(tmp_path: Path) -> None:
    path = tmp_path / "long.mcap"
    # Random positions compress poorly, so 300 snapshots of 25 fish fill many 32-KiB chunks.
    rng = np.random.default_rng(0)
    snapshots = []
    for tick in range(300):
        snapshot = _snapshot(tick, list(range(25)))
        snapshots.append(
            Snapshot(
                tick,
                float(tick),
                snapshot.ids,
                rng.uniform(0, 1.78, (25, 3)),
                rng.normal(size=(25, 3)),
                rng.uniform(-3, 3, 25),
                snapshot.neighbors_seen,
                snapshot.broadcasts,
            )
        )
    with open_recorder(path, {"fish": 25}) as recorder:
        for snapshot in snapshots:
            recorder.snapshot(snapshot.time, encode(snapshot))
            recorder.metrics(snapshot.time, {"tick": snapshot.tick})
    data = path.read_bytes()
    assert read_recording(path).complete
    counts = []
    for fraction in np.linspace(0.05, 0.98, 12):
        cut = tmp_path / "cut.mcap"
        cut.write_bytes(data[: int(fraction * len(data))])
        recording = read_recording(cut)
        assert not recording.complete
        read = len(recording.snapshots)
        assert recording.snapshots == snapshots[:read]  # exactly the first ones, none broken
        assert [m["tick"] for m in recording.metrics] == list(range(read))
        counts.append(read)
    assert counts == sorted(counts) and counts[-1] >= 250 and counts[0] < 50
    assert recording.note(cut) == (
        f"warning: {cut} was cut short (the run that wrote it was killed?): read "
        f"{counts[-1]} snapshots, up to tick {counts[-1] - 1}"
    )


def test_a_recording_changed_on_disk_is_refused_whole_or_cut(tmp_path: Path) -> None:
    # Eight bytes zeroed in the middle of a chunk: read without checksums, ticks went
    # missing silently.
    path = tmp_path / "run.mcap"
    rng = np.random.default_rng(0)
    with open_recorder(path, {"fish": 25}) as recorder:
        for tick in range(60):
            base = _snapshot(tick, list(range(25)))
            snapshot = Snapshot(
                tick, float(tick), base.ids, rng.uniform(0, 1.78, (25, 3)),
                rng.normal(size=(25, 3)), rng.uniform(-3, 3, 25), base.neighbors_seen,
                base.broadcasts,
            )  # fmt: skip
            recorder.snapshot(snapshot.time, encode(snapshot))
            recorder.metrics(snapshot.time, {"tick": tick})
    data = bytearray(path.read_bytes())
    assert len(data) > 60_000
    data[30_000:30_008] = bytes(8)
    for name, damaged in (("whole.mcap", data), ("cut.mcap", data[: len(data) // 2])):
        (tmp_path / name).write_bytes(damaged)
        with pytest.raises(RecordingError, match=r"is damaged: a chunk of it fails its checksum"):
            read_recording(tmp_path / name)
    # The first chunk's compressed bytes changed where they say how they are compressed:
    # the chunk fails before its checksum is seen. A cut file was read as cut there,
    # silently without the ticks of that chunk and after it.
    data = bytearray(path.read_bytes())
    records = StreamReader(io.BytesIO(bytes(data)), emit_chunks=True).records
    chunk = next(r for r in records if isinstance(r, Chunk))
    start = bytes(data).index(chunk.data)
    data[start : start + 4] = b"\xde\xad\xbe\xef"
    (tmp_path / "cut.mcap").write_bytes(data[: len(data) // 2])
    with pytest.raises(RecordingError, match=r"is damaged: a chunk of it cannot be read \(Zstd"):
        read_recording(tmp_path / "cut.mcap")


def test_a_large_swarm_cut_after_its_first_snapshot_reads_as_nothing_whole(
    tmp_path: Path,
) -> None:
    # 1 000 fish: one snapshot (about 90 kB) fills a chunk of its own, and its metrics go
    # into the next. Cut between the two, the snapshot is there without its metrics: read
    # as cut before it, so that nothing downstream pairs snapshots with missing metrics.
    path = tmp_path / "large.mcap"
    rng = np.random.default_rng(3)
    with open_recorder(path, {"fish": 1000}) as recorder:
        for tick in range(2):
            snapshot = Snapshot(
                tick, float(tick), np.arange(1000), rng.uniform(0, 1.78, (1000, 3)),
                rng.normal(size=(1000, 3)), rng.uniform(-3, 3, 1000),
                np.ones(1000, dtype=np.int64), np.zeros(1000, dtype=np.int64),
            )  # fmt: skip
            recorder.snapshot(snapshot.time, encode(snapshot))
            recorder.metrics(snapshot.time, {"tick": tick, "fitness": float("nan")})
    data = path.read_bytes()
    whole = read_recording(path)
    assert len(whole.snapshots) == 2 and np.isnan(whole.metrics[0]["fitness"])
    cuts = {}
    for end in range(1000, len(data), 251):
        (tmp_path / "cut.mcap").write_bytes(data[:end])
        recording = read_recording(tmp_path / "cut.mcap")
        assert len(recording.snapshots) == len(recording.metrics)
        cuts[len(recording.snapshots)] = end
    assert 0 in cuts and 1 in cuts  # both seen: cut before and after the first pair


def test_metrics_are_strict_json_and_undefined_ones_read_back_as_nan(tmp_path: Path) -> None:
    import json

    from mcap.reader import make_reader

    path = tmp_path / "nan.mcap"
    with open_recorder(path, {"fish": 2}) as recorder:
        snapshot = _snapshot(0, [0, 1])
        recorder.snapshot(0.0, encode(snapshot))
        recorder.metrics(0.0, {"shape_error": 0.5, "fitness": float("nan")})
    with path.open("rb") as stream:
        ((_, _, message),) = list(make_reader(stream).iter_messages(topics=["metrics"]))

    def refuse(word: str) -> None:
        raise ValueError(word)

    # As Foxglove's JSON.parse reads it: no bare NaN.
    assert json.loads(message.data, parse_constant=refuse) == {"shape_error": 0.5, "fitness": None}
    (metrics,) = read_recording(path).metrics
    assert metrics["shape_error"] == 0.5 and np.isnan(metrics["fitness"])


def test_a_recording_still_being_written_is_on_disk_up_to_its_last_chunk(tmp_path: Path) -> None:
    """What a run killed now would leave: every chunk the writer finished is in the file,
    not in a buffer of the process."""
    path = tmp_path / "live.mcap"
    rng = np.random.default_rng(0)
    with open_recorder(path, {"fish": 25}) as recorder:
        for tick in range(60):  # random positions compress poorly: several 32-KiB chunks
            snapshot = _snapshot(tick, list(range(25)))
            noisy = Snapshot(
                tick, float(tick), snapshot.ids, rng.random((25, 3)), rng.random((25, 3)),
                snapshot.yaw, snapshot.neighbors_seen, snapshot.broadcasts,
            )  # fmt: skip
            recorder.snapshot(noisy.time, encode(noisy))
            recorder.metrics(noisy.time, {"tick": tick})
            if tick == 0:  # from the first snapshot on, the header and the scenario are on disk
                started = read_recording(path)
                assert started.scenario == {"fish": 25} and started.snapshots == []
        # Read by another handle while the recorder is still open.
        meanwhile = read_recording(path)
    assert not meanwhile.complete
    assert 0 < len(meanwhile.snapshots) < 60
    assert [s.tick for s in meanwhile.snapshots] == list(range(len(meanwhile.snapshots)))
    assert read_recording(path).complete and len(read_recording(path).snapshots) == 60


def test_snapshots_read_back_in_tick_order_and_messages_are_numbered(tmp_path: Path) -> None:
    from mcap.reader import make_reader

    path = tmp_path / "r.mcap"
    with open_recorder(path, {}) as recorder:
        for tick in (2, 0, 1):  # as they may arrive
            recorder.snapshot(float(tick), encode(_snapshot(tick, [0])))
    assert [s.tick for s in read_recording(path).snapshots] == [0, 1, 2]
    with path.open("rb") as stream:
        numbers = [m.sequence for _, _, m in make_reader(stream).iter_messages()]
    assert sorted(numbers) == [0, 1, 2]


def test_a_file_holding_only_the_mcap_magic_is_an_empty_cut_recording(tmp_path: Path) -> None:
    path = tmp_path / "started.mcap"
    path.write_bytes(b"\x89MCAP0\r\n")  # what a run killed at its very start may leave
    recording = read_recording(path)
    assert not recording.complete and recording.snapshots == []
