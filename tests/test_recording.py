"""Recorder, reader, replay and offline replay on the in-memory bus (no zenoh, no processes)."""

from __future__ import annotations

import json
import threading
import time
from pathlib import Path

import pytest
from mcap.reader import make_reader
from mcap.writer import Writer

from groundstation.bus import InMemoryBus, Sample
from groundstation.config import Settings
from groundstation.recording import (
    RecordedMessage,
    Recorder,
    RecordingError,
    is_complete,
    iter_messages,
    recover,
    replay,
    replay_offline,
    run_replay_offline,
    schema_for_key,
    write_figures,
)

DRONES = ("cf1", "cf2", "lab-a-3")


def telemetry(seq: int, *, thrust_n: float = 0.2943) -> bytes:
    return json.dumps(
        {
            "seq": seq,
            "stamp_s": seq * 0.004,
            "accel_mps2": [0.0, 0.0, 9.81],
            "quat_wxyz": [1.0, 0.0, 0.0, 0.0],
            "thrust_n": thrust_n,
        },
        separators=(",", ":"),
    ).encode()


def publish_many(bus: InMemoryBus, n: int) -> list[Sample]:
    sent = []
    for i in range(n):
        sample = Sample(f"tether/{DRONES[i % 3]}/telemetry", telemetry(i // 3))
        bus.publish(sample.key, sample.payload)
        sent.append(sample)
    assert bus.flush(30.0)
    return sent


def read_reference(path: Path) -> list[tuple[str, bytes, int, int]]:
    """Read with the reference reader, in log-time order."""
    with path.open("rb") as fh:
        return [
            (channel.topic, message.data, message.log_time, message.publish_time)
            for _schema, channel, message in make_reader(fh).iter_messages(log_time_order=True)
        ]


@pytest.fixture
def bus():
    b = InMemoryBus()
    yield b
    b.close()


def test_every_sample_byte_equal_in_order(bus: InMemoryBus, tmp_path: Path) -> None:
    path = tmp_path / "rec.mcap"
    recorder = Recorder(bus, path)
    sent = publish_many(bus, 3000)
    bus.publish("other/ignored", b"{}")  # outside tether/**
    assert bus.flush()
    stats = recorder.close()

    got = read_reference(path)
    assert [(k, p) for k, p, _, _ in got] == [(s.key, s.payload) for s in sent]
    log_times = [t for _, _, t, _ in got]
    assert log_times == sorted(log_times)
    assert all(lt == pt for _, _, lt, pt in got)
    # Receive time is wall clock (ns since the epoch), close to now.
    assert abs(log_times[-1] / 1e9 - time.time()) < 60
    assert stats.messages == 3000 and stats.channels == 3 and stats.dropped == 0
    assert is_complete(path)


def test_channels_have_json_schemas(bus: InMemoryBus, tmp_path: Path) -> None:
    path = tmp_path / "rec.mcap"
    recorder = Recorder(bus, path, keyexprs=("**",))
    bus.publish("tether/cf1/telemetry", telemetry(0))
    bus.publish("tether/cf1/cmd/setpoint", b'{"stamp_s":1.0,"position_m":[0,0,1]}')
    bus.publish("lab/notes", b'{"text":"hi"}')
    assert bus.flush()
    recorder.close()

    with path.open("rb") as fh:
        summary = make_reader(fh).get_summary()
    assert summary is not None
    by_topic = {c.topic: c for c in summary.channels.values()}
    assert set(by_topic) == {"tether/cf1/telemetry", "tether/cf1/cmd/setpoint", "lab/notes"}
    for channel in by_topic.values():
        assert channel.message_encoding == "json"
        schema = summary.schemas[channel.schema_id]
        assert schema.encoding == "jsonschema"
        assert json.loads(schema.data)["type"] == "object"
    assert summary.schemas[by_topic["tether/cf1/telemetry"].schema_id].name == (
        "groundstation.Telemetry"
    )
    tele_schema = json.loads(summary.schemas[by_topic["tether/cf1/telemetry"].schema_id].data)
    assert "thrust_n" in tele_schema["properties"]
    assert summary.schemas[by_topic["tether/cf1/cmd/setpoint"].schema_id].name == (
        "groundstation.Setpoint"
    )
    assert summary.schemas[by_topic["lab/notes"].schema_id].name == "json"


@pytest.mark.parametrize(
    ("key", "name"),
    [
        ("tether/cf1/telemetry", "groundstation.Telemetry"),
        ("tether/cf1/reel", "groundstation.Reel"),
        ("tether/cf1/estimate", "groundstation.Estimate"),
        ("tether/cf1/follow", "groundstation.FollowCommand"),
        ("tether/cf1/cmd/setpoint", "groundstation.Setpoint"),
        ("tether/cf1/cmd/stop", "groundstation.Stop"),
        ("tether/cf1/truth", "groundstation.Truth"),
        ("tether/cf1/unknown", "json"),
        ("elsewhere/telemetry", "json"),
    ],
)
def test_schema_by_last_key_part(key: str, name: str) -> None:
    got_name, data = schema_for_key(key)
    assert got_name == name
    assert json.loads(data)["type"] == "object"


def test_overlapping_keyexprs_record_a_sample_once(bus: InMemoryBus, tmp_path: Path) -> None:
    path = tmp_path / "rec.mcap"
    recorder = Recorder(bus, path, keyexprs=("tether/**", "tether/*/telemetry", "lab/**"))
    bus.publish("tether/cf1/telemetry", telemetry(0))
    bus.publish("lab/x", b"{}")
    assert bus.flush()
    recorder.close()
    assert [m.key for m in iter_messages(path)] == ["tether/cf1/telemetry", "lab/x"]


def test_close_is_idempotent_and_unsubscribes(bus: InMemoryBus, tmp_path: Path) -> None:
    path = tmp_path / "rec.mcap"
    recorder = Recorder(bus, path)
    bus.publish("tether/cf1/telemetry", telemetry(0))
    assert bus.flush()
    first = recorder.close()
    bus.publish("tether/cf1/telemetry", telemetry(1))
    assert bus.flush()
    assert recorder.close() is first
    assert len(list(iter_messages(path))) == 1


def test_unwritable_path_raises_recording_error(bus: InMemoryBus, tmp_path: Path) -> None:
    with pytest.raises(RecordingError, match="cannot create recording"):
        Recorder(bus, tmp_path / "no" / "such" / "dir" / "rec.mcap")


def test_periodic_flush_makes_an_unfinished_file_readable(bus: InMemoryBus, tmp_path: Path) -> None:
    """Without close(), what was flushed is on disk and readable (the SIGKILL case)."""
    path = tmp_path / "rec.mcap"
    recorder = Recorder(bus, path, flush_interval_s=0.1)
    try:
        sent = publish_many(bus, 300)
        deadline = time.monotonic() + 10.0
        got: list[RecordedMessage] = []
        while time.monotonic() < deadline:
            got = list(iter_messages(path))
            if len(got) == len(sent):
                break
            time.sleep(0.05)
        assert not is_complete(path)
        assert [(m.key, m.payload) for m in got] == [(s.key, s.payload) for s in sent]
        with pytest.raises(RecordingError, match="not finished"):
            list(iter_messages(path, allow_truncated=False))
    finally:
        recorder.close()
    assert is_complete(path)


def test_truncated_file_yields_a_prefix(bus: InMemoryBus, tmp_path: Path) -> None:
    """Cut a finished file anywhere: the reader returns a prefix of what was recorded."""
    path = tmp_path / "rec.mcap"
    recorder = Recorder(bus, path, chunk_size=4096)
    sent = publish_many(bus, 2000)
    recorder.close()
    data = path.read_bytes()
    expected = [(s.key, s.payload) for s in sent]
    cut_path = tmp_path / "cut.mcap"
    counts = []
    for cut in range(0, len(data), max(1, len(data) // 37)):
        cut_path.write_bytes(data[:cut])
        if cut < 8:
            with pytest.raises(RecordingError):
                list(iter_messages(cut_path))
            continue
        got = [(m.key, m.payload) for m in iter_messages(cut_path)]
        assert got == expected[: len(got)]
        counts.append(len(got))
    assert counts == sorted(counts)
    assert counts[-1] > len(sent) // 2
    # recover() turns the readable part into a finished file.
    fixed = tmp_path / "fixed.mcap"
    assert recover(cut_path, fixed) == counts[-1]
    assert is_complete(fixed)
    assert [(k, p) for k, p, _, _ in read_reference(fixed)] == expected[: counts[-1]]


def test_not_an_mcap_file(tmp_path: Path) -> None:
    path = tmp_path / "x.mcap"
    path.write_bytes(b"hello, this is not MCAP at all")
    with pytest.raises(RecordingError, match="not an MCAP file"):
        list(iter_messages(path))


def write_recording(path: Path, messages: list[tuple[str, bytes, int]]) -> None:
    """A recording with chosen log times (ns), written with the mcap Writer directly."""
    with path.open("wb") as fh:
        writer = Writer(fh)
        writer.start()
        schema = writer.register_schema("json", "jsonschema", b'{"type":"object"}')
        channels: dict[str, int] = {}
        for key, payload, t_ns in messages:
            if key not in channels:
                channels[key] = writer.register_channel(key, "json", schema)
            writer.add_message(channels[key], t_ns, payload, t_ns)
        writer.finish()


def test_replay_keeps_order_and_timing(bus: InMemoryBus, tmp_path: Path) -> None:
    t0 = 1_700_000_000 * 10**9
    # 0.4 s of samples every 20 ms, a 0.6 s gap, one last sample: 1.0 s of recording.
    msgs = [("tether/cf1/telemetry", telemetry(i), t0 + i * 20_000_000) for i in range(21)]
    msgs.append(("tether/cf2/reel", b'{"stamp_s":1.0,"length_m":1.5}', t0 + 1_000_000_000))
    path = tmp_path / "in.mcap"
    write_recording(path, msgs)

    received: list[tuple[float, Sample]] = []
    done = threading.Event()

    def on_sample(sample: Sample) -> None:
        received.append((time.monotonic(), sample))
        if len(received) == len(msgs):
            done.set()

    sub = bus.subscribe("tether/**", on_sample)
    try:
        stats = replay(bus, path, speed=2.0)
        assert done.wait(5.0)
    finally:
        sub.close()
    assert [(s.key, s.payload) for _, s in received] == [(k, p) for k, p, _ in msgs]
    assert stats.messages == len(msgs)
    assert stats.span_s == pytest.approx(1.0)
    # 1.0 s of recording at speed 2: about 0.5 s (generous bounds for a loaded machine).
    elapsed = received[-1][0] - received[0][0]
    assert 0.4 < elapsed < 2.0
    gap = received[-1][0] - received[-2][0]
    assert gap > 0.25  # the 0.6 s gap, halved, is still there


def test_replay_stops_on_event(bus: InMemoryBus, tmp_path: Path) -> None:
    t0 = 10**18
    msgs = [("tether/cf1/telemetry", telemetry(i), t0 + i * 10**9) for i in range(30)]
    path = tmp_path / "in.mcap"
    write_recording(path, msgs)
    stop = threading.Event()
    timer = threading.Timer(0.3, stop.set)
    timer.start()
    try:
        started = time.monotonic()
        stats = replay(bus, path, stop_event=stop)
    finally:
        timer.cancel()
    assert time.monotonic() - started < 5.0
    assert 1 <= stats.messages < 30


def test_replay_rejects_bad_speed(bus: InMemoryBus, tmp_path: Path) -> None:
    path = tmp_path / "in.mcap"
    write_recording(path, [])
    with pytest.raises(ValueError, match="speed"):
        replay(bus, path, speed=0.0)


class FakePipeline:
    """Echoes each telemetry as an estimate; counts ticks."""

    def __init__(self) -> None:
        self.handled: list[tuple[str, float]] = []
        self.ticks: list[float] = []

    def handle(self, sample: Sample, now_s: float) -> list[Sample]:
        self.handled.append((sample.key, now_s))
        if sample.key.endswith("/telemetry"):
            drone = sample.key.split("/")[1]
            return [Sample(f"tether/{drone}/estimate", b'{"new":true}')]
        return []

    def tick(self, now_s: float) -> list[Sample]:
        self.ticks.append(now_s)
        return []


def test_offline_replay_writes_inputs_and_new_outputs(tmp_path: Path) -> None:
    t0 = 1_700_000_000 * 10**9
    msgs = [
        ("tether/cf1/reel", b'{"stamp_s":0.0,"length_m":1.5}', t0),
        ("tether/cf1/telemetry", telemetry(0), t0 + 10_000_000),
        ("tether/cf1/estimate", b'{"old":true}', t0 + 11_000_000),
        ("tether/cf1/truth", b'{"t":1}', t0 + 12_000_000),
        ("tether/cf1/telemetry", telemetry(1), t0 + 500_000_000),
        ("tether/cf1/cmd/stop", b'{"stamp_s":1.0,"reason":"x"}', t0 + 501_000_000),
    ]
    src = tmp_path / "in.mcap"
    out = tmp_path / "out.mcap"
    write_recording(src, msgs)
    pipeline = FakePipeline()
    assert replay_offline(src, out, pipeline) == 2

    got = [(k, p, t) for k, p, t, _ in read_reference(out)]
    assert got == [
        ("tether/cf1/reel", msgs[0][1], t0),
        ("tether/cf1/telemetry", msgs[1][1], t0 + 10_000_000),
        ("tether/cf1/estimate", b'{"new":true}', t0 + 10_000_000),
        ("replay/original/tether/cf1/estimate", b'{"old":true}', t0 + 11_000_000),
        ("tether/cf1/truth", b'{"t":1}', t0 + 12_000_000),
        ("tether/cf1/telemetry", msgs[4][1], t0 + 500_000_000),
        ("tether/cf1/estimate", b'{"new":true}', t0 + 500_000_000),
        ("replay/original/tether/cf1/cmd/stop", msgs[5][1], t0 + 501_000_000),
    ]
    # Inputs only (truth and the original outputs never reach the pipeline), at log time.
    assert [k for k, _ in pipeline.handled] == [
        "tether/cf1/reel",
        "tether/cf1/telemetry",
        "tether/cf1/telemetry",
    ]
    assert pipeline.handled[1][1] == pytest.approx((t0 + 10_000_000) / 1e9)
    # Ticks every 50 ms of log time up to the last input.
    assert len(pipeline.ticks) == 10


def test_offline_replay_with_the_real_pipeline(tmp_path: Path) -> None:
    """One estimate per accepted telemetry (the contract), on the service's own Pipeline."""
    t0 = 1_700_000_000 * 10**9
    msgs = [
        ("tether/cf1/telemetry", telemetry(i, thrust_n=0.2943 + 0.05), t0 + i * 4_000_000)
        for i in range(200)
    ]
    src = tmp_path / "in.mcap"
    out = tmp_path / "out.mcap"
    write_recording(src, msgs)
    assert run_replay_offline(Settings(), src, out) == 0
    estimates = [m for m in iter_messages(out) if m.key == "tether/cf1/estimate"]
    assert len(estimates) == 200
    seqs = [json.loads(m.payload)["seq"] for m in estimates]
    assert seqs == list(range(200))


def test_figures_from_a_replayed_recording(tmp_path: Path) -> None:
    """PNG files per drone (Agg backend; nothing is shown)."""
    t0 = 1_700_000_000 * 10**9
    msgs: list[tuple[str, bytes, int]] = []
    for i in range(50):
        t = t0 + i * 20_000_000
        msgs.append(("tether/cf1/telemetry", telemetry(i, thrust_n=0.35), t))
        estimate = {
            "seq": i,
            "stamp_s": i * 0.02,
            "tension_n": [-0.05, 0.0, -0.04],
            "tension_std_n": [0.01, 0.01, 0.01],
            "horizontal_n": 0.05,
            "vertical_n": 0.04,
            "position_m": [0.5, 0.0, 1.0] if i > 5 else None,
            "follow": {"enabled": False, "active": False, "threshold_n": 0.15},
        }
        msgs.append(("tether/cf1/estimate", json.dumps(estimate).encode(), t))
        truth = {
            "stamp_s": i * 0.02,
            "position_m": [0.5, 0.0, 1.0],
            "velocity_mps": [0.0, 0.0, 0.0],
            "tension_n": [-0.05, 0.0, -0.04],
            "length_m": 1.6,
            "base_m": [0.0, 0.0, 0.754],
            "floor_contact": False,
            "taut": True,
            "armed": True,
            "on_ground": False,
        }
        msgs.append(("tether/cf1/truth", json.dumps(truth).encode(), t + 1))
    src = tmp_path / "in.mcap"
    write_recording(src, msgs)
    figures = tmp_path / "fig"
    written = write_figures(src, figures)
    assert sorted(p.name for p in written) == ["cf1_position.png", "cf1_tension.png"]
    pngs = sorted(p.name for p in figures.iterdir())
    assert pngs == ["cf1_position.png", "cf1_tension.png"]
    for name in pngs:
        assert (figures / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


# -- A corrupt recording is read where it can be; an empty one says so ---------------------


def _chunked(bus: InMemoryBus, path: Path, n: int = 3000) -> list[Sample]:
    recorder = Recorder(bus, path, chunk_size=4096)
    sent = publish_many(bus, n)
    recorder.close()
    return sent


def _flip(path: Path, at: int, n: int = 8) -> None:
    data = bytearray(path.read_bytes())
    for k in range(n):
        data[at + k] ^= 0xFF
    path.write_bytes(bytes(data))


def _chunk_spans(path: Path) -> list[tuple[int, int]]:
    with path.open("rb") as fh:
        summary = make_reader(fh).get_summary()
    assert summary is not None
    return sorted(
        (c.chunk_start_offset, c.chunk_start_offset + c.chunk_length) for c in summary.chunk_indexes
    )


def _is_a_gap_of(got: list[tuple[str, bytes]], sent: list[tuple[str, bytes]]) -> int:
    """``got`` is ``sent`` less one contiguous run of messages: its length."""
    lost = len(sent) - len(got)
    start = next((i for i, (a, b) in enumerate(zip(got, sent, strict=False)) if a != b), len(got))
    assert got == sent[:start] + sent[start + lost :]
    return lost


@pytest.mark.parametrize("finished", [True, False])
def test_corrupt_chunk_is_skipped_named_and_counted(
    bus: InMemoryBus, tmp_path: Path, caplog: pytest.LogCaptureFixture, finished: bool
) -> None:
    """8 flipped bytes in the middle chunk (before: a zstandard traceback): every other
    message is read, in order; the warning names the chunk and the messages it held."""
    path = tmp_path / "rec.mcap"
    sent = [(s.key, s.payload) for s in _chunked(bus, path)]
    spans = _chunk_spans(path)
    k = len(spans) // 2
    start, end = spans[k]
    _flip(path, (start + end) // 2)
    if not finished:  # cut the summary off: the sequential reader
        path.write_bytes(path.read_bytes()[: spans[-1][1]])
        assert not is_complete(path)
    with caplog.at_level("WARNING", logger="groundstation.recording.reader"):
        got = [(m.key, m.payload) for m in iter_messages(path, require_messages=True)]
    lost = _is_a_gap_of(got, sent)
    assert 0 < lost < 60  # one chunk of 4 kB
    text = caplog.text
    if finished:
        assert f"chunk {k + 1} of {len(spans)} (bytes {start}-{end}) is corrupt" in text
    else:
        assert f"chunk {k + 1} (ending at byte " in text
    assert f"{lost} messages lost" in text
    assert f"{len(got)} messages read; 1 corrupt chunk(s) skipped, {lost} messages lost" in text


def test_every_chunk_corrupt_holds_nothing(bus: InMemoryBus, tmp_path: Path) -> None:
    path = tmp_path / "rec.mcap"
    sent = _chunked(bus, path, 300)
    for start, end in _chunk_spans(path):
        _flip(path, (start + end) // 2)
    assert list(iter_messages(path)) == []  # a reader that asks for nothing gets nothing
    with pytest.raises(
        RecordingError,
        match=rf"holds no readable message: every chunk is corrupt \(\d+, {len(sent)} messages",
    ):
        list(iter_messages(path, require_messages=True))


def test_a_100_byte_mcap_holds_nothing(bus: InMemoryBus, tmp_path: Path) -> None:
    full = tmp_path / "rec.mcap"
    _chunked(bus, full, 300)
    path = tmp_path / "small.mcap"
    path.write_bytes(full.read_bytes()[:100])
    assert list(iter_messages(path)) == []
    with pytest.raises(
        RecordingError,
        match=r"small\.mcap' holds no readable message: it ends after 100 bytes, before its "
        r"first complete chunk",
    ):
        list(iter_messages(path, require_messages=True))


def test_replay_offline_and_calibrate_on_damaged_recordings(
    bus: InMemoryBus, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The commands: a corrupt chunk costs its messages, exit 0; nothing readable, exit 2
    with one line saying so, and no output written."""
    from groundstation.cli import main

    path = tmp_path / "rec.mcap"
    sent = _chunked(bus, path)
    spans = _chunk_spans(path)
    _flip(path, sum(spans[len(spans) // 2]) // 2)
    out = tmp_path / "out.mcap"
    assert main(["replay", "--offline", str(path), "--out", str(out)]) == 0
    inputs = [m for m in iter_messages(out) if m.key.endswith("/telemetry")]
    assert 0 < len(sent) - len(inputs) < 60
    small = tmp_path / "small.mcap"
    small.write_bytes(path.read_bytes()[:100])
    capsys.readouterr()
    out.unlink()
    assert main(["replay", "--offline", str(small), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "small.mcap' holds no readable message: it ends after 100 bytes" in err
    assert not out.exists()
    cal = tmp_path / "cal.toml"
    assert main(["calibrate", str(small), "--out", str(cal)]) == 2
    assert "small.mcap' holds no readable message" in capsys.readouterr().err
    assert not cal.exists()
