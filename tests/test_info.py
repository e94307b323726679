"""``groundstation info``: what a recording holds, read from a file whose content is known."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from groundstation.cli import main
from groundstation.recording.info import GAP_PERIODS, format_info, recording_info
from groundstation.recording.reader import RecordedMessage, copy_messages

T0_NS = 1_700_000_000 * 10**9


def _tel(seq: int, stamp_s: float, *, mocap: bool, vbat_v: float) -> bytes:
    tel: dict[str, object] = {
        "seq": seq,
        "stamp_s": stamp_s,
        "accel_mps2": [0.0, 0.0, 9.81],
        "quat_wxyz": [1.0, 0.0, 0.0, 0.0],
        "thrust_n": 0.3,
        "armed": True,
        "vbat_v": vbat_v,
    }
    if mocap:
        tel["position_m"] = [1.0, 0.0, 1.0]
    if seq >= 750:
        tel["attitude_source"] = "external"
    return json.dumps(tel).encode()


@pytest.fixture
def flight(tmp_path: Path) -> Path:
    """cf1 at 100 Hz for 10 s of its own clock, received at twice that speed (a replay at
    --speed 2), with one 0.5 s gap, one invalid Telemetry, mocap in the first half, the
    attitude said to be external in the last quarter, a reel and estimates; cf2: one reel
    message only."""
    msgs: list[RecordedMessage] = []
    t = T0_NS
    msgs.append(RecordedMessage("tether/cf2/reel", b'{"stamp_s":0,"length_m":1.5}', t, t))
    for i in range(1000):
        t = T0_NS + i * 5_000_000 + (500_000_000 if i >= 600 else 0)
        payload = _tel(i, 10.0 + i * 0.01, mocap=i < 500, vbat_v=4.1 - i * 0.0005)
        msgs.append(RecordedMessage("tether/cf1/telemetry", payload, t, t))
        est = {"seq": i, "calibration": "lab-cal.toml 2026-12-01" if i < 10 else "none"}
        msgs.append(RecordedMessage("tether/cf1/estimate", json.dumps(est).encode(), t, t))
    msgs.append(RecordedMessage("tether/cf1/telemetry", b'{"seq": "broken"}', t + 1, t + 1))
    msgs.append(RecordedMessage("tether/cf1/reel", b'{"stamp_s":0,"length_m":1.6}', t + 2, t + 2))
    msgs.append(RecordedMessage("lab/notes", b"{}", t + 3, t + 3))
    path = tmp_path / "flight.mcap"
    copy_messages(msgs, path)
    return path


def test_the_summary_says_what_the_file_holds(flight: Path) -> None:
    info = recording_info(flight)
    assert info.finished and info.messages == 2004
    assert info.keys["tether/cf1/telemetry"].count == 1001
    assert info.keys["lab/notes"].count == 1
    assert list(info.drones) == ["cf1", "cf2"]
    cf1 = info.drones["cf1"]
    assert cf1.telemetry == 1000 and cf1.invalid_telemetry == 1
    assert cf1.stamp_s == pytest.approx((10.0, 19.99))  # the drone's clock, not receive time
    assert info.span_s == pytest.approx(999 * 0.005 + 0.5, abs=1e-6)  # receive clock
    assert cf1.with_mocap == 500 and cf1.reel == 1 and cf1.estimates == 1000
    assert cf1.vbat_v == pytest.approx((4.1 - 999 * 0.0005, 4.1))
    assert cf1.calibrations == ["lab-cal.toml 2026-12-01", "none"]
    assert cf1.attitude_sources == {"not said": 750, "external": 250}
    assert cf1.position_sources == {"mocap": 500}
    assert cf1.median_period_s == pytest.approx(0.005)
    assert len(cf1.gaps) == 1
    start_s, length_s = cf1.gaps[0]
    assert start_s == pytest.approx(599 * 0.005) and length_s == pytest.approx(0.505)
    assert length_s > GAP_PERIODS * cf1.median_period_s
    assert info.drones["cf2"].telemetry == 0 and info.drones["cf2"].reel == 1
    text = format_info(info)
    for needle in (
        "finished",
        "drones:    cf1, cf2",
        "drone clock 10.00 to 19.99 s",
        "motion capture in 50 %",
        "invalid telemetry: 1",
        "calibration applied: lab-cal.toml 2026-12-01; none",
        "gaps in telemetry (> 5 periods): 1, longest 0.505 s",
        "battery 4.10 to 3.60 V",
        "attitude   not said 75 %, external 25 %; position   mocap 50 %",
    ):
        assert needle in text, text


def test_the_command_reads_a_cut_file_and_writes_nothing(
    flight: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    cut = tmp_path / "cut.mcap"
    data = flight.read_bytes()
    cut.write_bytes(data[: len(data) * 2 // 3])  # a killed recorder: no footer
    before = sorted(p.name for p in tmp_path.iterdir())
    assert main(["info", str(flight), str(cut)]) == 0
    out = capsys.readouterr().out
    assert "flight.mcap" in out and "NOT finished" in out
    assert sorted(p.name for p in tmp_path.iterdir()) == before
    assert main(["info", "--json", str(flight)]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["messages"] == 2004 and doc["drones"]["cf1"]["telemetry"] == 1000
    assert main(["info", str(tmp_path / "nothing.mcap")]) == 2
    assert "no such file" in capsys.readouterr().err
