"""No command destroys a user's file: outputs checked first, written whole, with the umask.

The three ways a lab lost a flight (``replay j.mcap --offline --out j.mcap``, ``calibrate
c1.mcap --out c1.mcap``, ``record --out`` onto an existing flight) each leave the file
byte-identical; ``--force`` replaces an output, never an input. The end-to-end check with a
real recording made by ``sim`` + ``record`` is tests/integration/test_user_outputs.py.
"""

from __future__ import annotations

import os
import stat
from pathlib import Path

import pytest

from groundstation.cli import main
from groundstation.outputs import NewFile, OutputError, check_output, file_mode
from groundstation.recording import iter_messages
from groundstation.sim.scenarios import PAPER_HOVER_SPOTS_M
from tests.calib_synth import Truth, flight, write_mcap

TRUTH = Truth(thrust_scale=0.95, about_x_rad=0.01, about_y_rad=-0.02, bias_mps2=(0.1, -0.1, 0.1))


@pytest.fixture(scope="module")
def flights(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """Two short recorded flights, one with a reel message and one without (the second
    stands in for an untethered flight: only the absence of tether messages matters here)."""
    d = tmp_path_factory.mktemp("flights")
    spots = list(PAPER_HOVER_SPOTS_M[:2])
    tethered, untethered = d / "tethered.mcap", d / "untethered.mcap"
    write_mcap(str(tethered), flight(spots, TRUTH, seed=1))
    write_mcap(
        str(untethered),
        flight(spots, TRUTH, seed=2),
        reel_length_m=None,
    )
    return {"tethered": tethered, "untethered": untethered}


def _copy(src: Path, dst: Path) -> Path:
    dst.write_bytes(src.read_bytes())
    return dst


def _no_partials(d: Path) -> None:
    assert not list(d.glob(".*.partial")), list(d.iterdir())


# --------------------------------------------------------------------- the building blocks


def test_check_output_refuses_an_input_even_with_force(tmp_path: Path) -> None:
    f = tmp_path / "j.mcap"
    f.write_bytes(b"flight")
    for force in (False, True):
        with pytest.raises(OutputError, match="is also an input"):
            check_output(f, inputs=[f], force=force)
        # the same file under another name
        with pytest.raises(OutputError, match="is also an input"):
            check_output(tmp_path / "." / "j.mcap", inputs=[f], force=force)
    link = tmp_path / "link.mcap"
    link.symlink_to(f)
    with pytest.raises(OutputError, match="is also an input"):
        check_output(link, inputs=[f], force=True)


def test_check_output_refuses_an_existing_file_unless_forced(tmp_path: Path) -> None:
    f = tmp_path / "out.mcap"
    assert check_output(f) == f  # new: fine
    f.write_bytes(b"x")
    with pytest.raises(OutputError, match=r"exists: refusing to replace it .*--force"):
        check_output(f)
    assert check_output(f, force=True) == f
    with pytest.raises(OutputError, match="is a directory"):
        check_output(tmp_path, force=True)
    with pytest.raises(OutputError, match="does not exist"):
        check_output(tmp_path / "no" / "out.mcap")
    with pytest.raises(OutputError, match="is a file, not a directory"):
        check_output(f, directory=True, flag="--figures")


def test_new_file_is_whole_or_nothing_and_takes_the_umask(tmp_path: Path) -> None:
    target = tmp_path / "out.bin"
    old = os.umask(0o022)
    try:
        assert file_mode() == 0o644
        with NewFile(target) as out:
            out.stream.write(b"abc")
            assert not target.exists()  # nothing under the name until complete
        assert target.read_bytes() == b"abc"
        assert stat.S_IMODE(target.stat().st_mode) == 0o644
        # a failure leaves the existing file as it was, and no temporary file
        with pytest.raises(RuntimeError), NewFile(target, force=True) as out:
            out.stream.write(b"half")
            raise RuntimeError("disk full")
        assert target.read_bytes() == b"abc"
        _no_partials(tmp_path)
        # without force, a file that appeared meanwhile is not replaced
        late = tmp_path / "late.bin"
        out = NewFile(late)
        out.stream.write(b"new")
        late.write_bytes(b"someone else's")
        with pytest.raises(OutputError, match="appeared while it was being written"):
            out.commit()
        assert late.read_bytes() == b"someone else's"
        _no_partials(tmp_path)
    finally:
        os.umask(old)


def test_a_recording_grows_in_place_and_refuses_an_existing_file(tmp_path: Path) -> None:
    target = tmp_path / "rec.mcap"
    out = NewFile(target, grow_in_place=True)
    out.stream.write(b"part")
    out.stream.flush()
    assert target.read_bytes() == b"part"  # a killed recorder leaves this on disk
    out.discard()
    assert target.read_bytes() == b"part"  # kept: it is what was recorded
    with pytest.raises(OutputError, match="exists"):
        NewFile(target, grow_in_place=True)
    assert target.read_bytes() == b"part"


# --------------------------------------------------------------------- the commands


def test_replay_offline_onto_its_input_leaves_it_byte_identical(
    flights: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    j = _copy(flights["tethered"], tmp_path / "j.mcap")
    before = j.read_bytes()
    for extra in ([], ["--force"]):
        assert main(["replay", str(j), "--offline", "--out", str(j), *extra]) == 2
        err = capsys.readouterr().err
        assert "is also an input" in err and "Traceback" not in err
        assert j.read_bytes() == before
    _no_partials(tmp_path)


def test_replay_offline_refuses_an_existing_output_unless_forced(
    flights: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    j = _copy(flights["tethered"], tmp_path / "j.mcap")
    other = _copy(flights["untethered"], tmp_path / "other.mcap")
    before = other.read_bytes()
    assert main(["replay", str(j), "--offline", "--out", str(other)]) == 2
    assert "exists: refusing to replace it" in capsys.readouterr().err
    assert other.read_bytes() == before
    assert main(["replay", str(j), "--offline", "--out", str(other), "--force"]) == 0
    keys = {m.key for m in iter_messages(other)}
    assert "tether/cf1/estimate" in keys and "tether/cf1/reel" in keys  # j's, re-estimated
    _no_partials(tmp_path)


def test_replay_figures_onto_a_file_or_old_figures_is_a_clear_error(
    flights: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    j = flights["tethered"]
    a_file = tmp_path / "notes.txt"
    a_file.write_text("lab notes")
    out = tmp_path / "out.mcap"
    rc = main(["replay", str(j), "--offline", "--out", str(out), "--figures", str(a_file)])
    err = capsys.readouterr().err
    assert rc == 2 and "is a file, not a directory" in err and "Traceback" not in err
    assert a_file.read_text() == "lab notes" and not out.exists()  # checked before reading
    figs = tmp_path / "figs"
    figs.mkdir()
    (figs / "cf1_tension.png").write_bytes(b"an earlier figure")
    rc = main(["replay", str(j), "--offline", "--out", str(out), "--figures", str(figs)])
    assert rc == 2 and "already holds figures (cf1_tension.png)" in capsys.readouterr().err
    assert (figs / "cf1_tension.png").read_bytes() == b"an earlier figure" and not out.exists()
    # Asked with --force, the figures are replaced (and the directory's other files kept).
    (figs / "notes.txt").write_text("kept")
    rc = main(["replay", str(j), "--offline", "--out", str(out), "--figures", str(figs), "--force"])
    assert rc == 0, capsys.readouterr().err
    png = (figs / "cf1_tension.png").read_bytes()
    assert png.startswith(b"\x89PNG") and (figs / "notes.txt").read_text() == "kept"
    _no_partials(tmp_path)
    _no_partials(figs)


def test_replay_out_without_offline_is_an_error(
    flights: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["replay", str(flights["tethered"]), "--out", str(tmp_path / "x.mcap")]) == 2
    assert "need --offline" in capsys.readouterr().err


def test_calibrate_onto_a_recording_leaves_it_byte_identical(
    flights: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    c1 = _copy(flights["tethered"], tmp_path / "c1.mcap")
    cfg = tmp_path / "lab.toml"
    cfg.write_text("[drone]\nmass_kg = 0.030\n")
    before, cfg_before = c1.read_bytes(), cfg.read_bytes()
    for out in (c1, cfg):
        for extra in ([], ["--force"]):
            rc = main(["calibrate", str(c1), "--config", str(cfg), "--out", str(out), *extra])
            assert rc == 2
            err = capsys.readouterr()
            assert "is also an input" in err.err and "wrote" not in err.out
    assert c1.read_bytes() == before and cfg.read_bytes() == cfg_before
    _no_partials(tmp_path)


def test_calibrate_refuses_an_existing_output_unless_forced_and_writes_with_the_umask(
    flights: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "lab-cal.toml"
    out.write_text("# an earlier calibration\n")
    args = ["calibrate", str(flights["tethered"]), "--out", str(out)]
    assert main(args) == 2
    assert "exists: refusing to replace it" in capsys.readouterr().err
    assert out.read_text() == "# an earlier calibration\n"
    old = os.umask(0o022)
    try:
        assert main([*args, "--force"]) == 0
    finally:
        os.umask(old)
    assert "[drones.cf1.calibration]" in out.read_text()
    assert stat.S_IMODE(out.stat().st_mode) == 0o644  # readable by the service's user
    _no_partials(tmp_path)


def test_calibrate_untethered_refuses_tether_messages_unless_detached(
    flights: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "cal.toml"
    rc = main(["calibrate", "--untethered", str(flights["tethered"]), "--out", str(out)])
    err = capsys.readouterr().err
    assert rc == 2 and "hold tether messages" in err and "tethered.mcap (1 for cf1)" in err
    assert "--tether-detached" in err and not out.exists()
    detached = ["--untethered", "--tether-detached", str(flights["tethered"])]
    rc = main(["calibrate", *detached, "--out", str(out)])
    assert rc == 0 and out.exists()
    # A recording with no tether messages needs no such word.
    out2 = tmp_path / "cal2.toml"
    rc = main(["calibrate", "--untethered", str(flights["untethered"]), "--out", str(out2)])
    assert rc == 0, capsys.readouterr().err


def test_record_onto_an_existing_flight_is_refused_before_the_bus_opens(
    flights: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    keep = _copy(flights["tethered"], tmp_path / "keep.mcap")
    before = keep.read_bytes()
    # No router anywhere: the refusal must come first (else: a zenoh error, or a truncation).
    rc = main(["record", "--out", str(keep), "--connect", "tcp/127.0.0.1:9"])
    err = capsys.readouterr().err
    assert rc == 2 and "keep.mcap' exists: refusing to replace it" in err, err
    assert keep.read_bytes() == before
    rc = main(["serve", "--headless", "--record", str(keep), "--connect", "tcp/127.0.0.1:9"])
    assert rc == 2 and "--record" in capsys.readouterr().err
    assert keep.read_bytes() == before


def test_a_time_in_the_name_gives_a_restarted_service_a_new_file() -> None:
    from groundstation.outputs import expand_time

    assert expand_time("/var/x/session-{time}.mcap", 0.0) == "/var/x/session-19700101T000000Z.mcap"
    assert expand_time("flight.mcap", 0.0) == "flight.mcap"
