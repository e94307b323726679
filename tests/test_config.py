"""Configuration: file < environment < CLI, per-drone overrides, errors that name key and value."""

from pathlib import Path

import pytest

from groundstation.config import ConfigError, load_settings

REPO = Path(__file__).resolve().parents[1]


def test_defaults_match_the_contract() -> None:
    s = load_settings(None, use_env=False)
    assert s.zenoh.mode == "peer"
    assert s.zenoh.connect == () and s.zenoh.listen == ()
    assert s.zenoh.multicast_scouting is False
    assert s.drone.mass_kg == pytest.approx(0.030)
    assert s.tether.weight_n_per_m == pytest.approx(0.05)
    assert s.tether.length_m == pytest.approx(1.6)
    assert s.base.position_m == (0.0, 0.0, 0.754)
    assert s.base.floor_z_m == 0.0
    assert s.web.host == "127.0.0.1" and s.web.port == 8080


@pytest.mark.parametrize("name", ["default.toml", "sim.toml", "reel.toml"])
def test_example_configs_load(name: str) -> None:
    path = REPO / "config" / name
    if not path.exists():
        pytest.fail(f"config/{name} is missing")
    load_settings(path, use_env=False)


def test_layers_file_env_cli(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    cfg = tmp_path / "c.toml"
    cfg.write_text(
        '[tether]\nlength_m = 2.0\nweight_n_per_m = 0.06\n[zenoh]\nmode = "client"\n'
        "[drones.cf2.tether]\nweight_n_per_m = 0.07\n"
    )
    monkeypatch.setenv("GROUNDSTATION_TETHER__WEIGHT_N_PER_M", "0.04")
    monkeypatch.setenv("GROUNDSTATION_TETHER__LENGTH_M", "3.0")
    s = load_settings(cfg, {"tether": {"length_m": 2.5}})
    assert s.tether.weight_n_per_m == pytest.approx(0.04)  # env beats file
    assert s.tether.length_m == pytest.approx(2.5)  # CLI beats env
    assert s.zenoh.mode == "client"
    assert s.for_drone("cf2").tether.weight_n_per_m == pytest.approx(0.07)
    assert s.for_drone("cf2").tether.length_m == pytest.approx(2.5)
    assert s.for_drone("other").tether.weight_n_per_m == pytest.approx(0.04)


@pytest.mark.parametrize(
    ("text", "needle"),
    [
        ("[tether]\nweight_n_per_m = -0.05\n", "tether.weight_n_per_m = -0.05"),
        ("[tether]\nlength_m = 0\n", "tether.length_m = 0"),
        ('[zenoh]\nmode = "satellite"\n', "zenoh.mode = 'satellite'"),
        ("[base]\nposition_m = [0.0, 0.0]\n", "base.position_m"),
        ("[tethr]\nlength_m = 1\n", "tethr"),
        ("[drones.cf1.tether]\nweight_n_per_m = 0.0\n", "drones.cf1.tether.weight_n_per_m = 0.0"),
        ('[drones."bad id!"]\n', "bad id!"),
        ("[tether\n", "not valid TOML"),
        ('[tether]\nlength_m = "1.6"\n', "tether.length_m = '1.6': a number is required"),
        ('[sim]\nmocap = "false"\n', "sim.mocap = 'false': true or false is required"),
        ("[sim]\nmocap = 1\n", "sim.mocap = 1: true or false is required"),
        ("[web]\nport = true\n", "web.port = True: a number is required"),
        ('[base]\nposition_m = [0.0, "0", 0.7]\n', "base.position_m = [0.0, '0', 0.7]"),
        ('[drones.cf2.tether]\nlength_m = "2"\n', "drones.cf2.tether.length_m = '2'"),
        ('[zenoh]\nconnect = ["bogus"]\n', "zenoh.connect = ['bogus']: 'bogus' is not a zenoh"),
        ("[follow]\nthreshold_n = 0.01\n", "follow.threshold_n = 0.01: below"),
    ],
)
def test_bad_config_names_key_and_value(tmp_path: Path, text: str, needle: str) -> None:
    cfg = tmp_path / "bad.toml"
    cfg.write_text(text)
    with pytest.raises(ConfigError) as info:
        load_settings(cfg, use_env=False)
    assert needle in str(info.value)


def test_bad_env_value(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("GROUNDSTATION_DRONE__MASS_KG", "heavy")
    with pytest.raises(ConfigError, match=r"drone\.mass_kg = 'heavy'"):
        load_settings(None)


def test_missing_file() -> None:
    with pytest.raises(ConfigError, match="cannot read config file"):
        load_settings("/nonexistent/gs.toml", use_env=False)


def test_env_values_are_strings_and_still_accepted(monkeypatch: pytest.MonkeyPatch) -> None:
    # Strict scalars apply to the file and the CLI; the environment only has strings.
    monkeypatch.setenv("GROUNDSTATION_SIM__MOCAP", "false")
    monkeypatch.setenv("GROUNDSTATION_DRONES__CF2__TETHER__LENGTH_M", "2.5")
    s = load_settings(None)
    assert s.sim.mocap is False
    assert s.for_drone("cf2").tether.length_m == pytest.approx(2.5)


def test_integers_are_fine_where_floats_are_expected(tmp_path: Path) -> None:
    cfg = tmp_path / "c.toml"
    cfg.write_text("[tether]\nlength_m = 2\n[base]\nposition_m = [0, 0, 1]\n")
    s = load_settings(cfg, use_env=False)
    assert s.tether.length_m == 2.0 and s.base.position_m == (0.0, 0.0, 1.0)


def test_localization_section() -> None:
    s = load_settings(None, {"localization": {"azimuth": "mocap"}}, use_env=False)
    assert s.localization.azimuth == "mocap" and s.localization.elevation is True
    with pytest.raises(ConfigError, match=r"localization\.azimuth = 'compass'"):
        load_settings(None, {"localization": {"azimuth": "compass"}}, use_env=False)


def test_calibration_vbat_range(tmp_path: Path) -> None:
    """[calibration] thrust_vbat_range_v: optional, [lo, hi] volts, per drone like the rest."""
    assert load_settings(None, use_env=False).calibration.thrust_vbat_range_v is None
    path = tmp_path / "cal.toml"
    path.write_text(
        "[calibration]\nthrust_vbat_range_v = [3.95, 4.02]\n"
        "[drones.cf2.calibration]\nthrust_vbat_range_v = [3.6, 4.1]\n"
    )
    settings = load_settings(path, use_env=False)
    assert settings.for_drone("cf1").calibration.thrust_vbat_range_v == (3.95, 4.02)
    assert settings.for_drone("cf2").calibration.thrust_vbat_range_v == (3.6, 4.1)
    for bad, needle in (
        ("[4.1, 3.9]", r"calibration\.thrust_vbat_range_v = \[4\.1, 3\.9\].*lo <= hi"),
        ("[0, 4.0]", r"calibration\.thrust_vbat_range_v = \[0, 4\.0\]"),
        ("[3.9]", r"calibration\.thrust_vbat_range_v"),
        ("[3.9, 4.0, 4.1]", r"calibration\.thrust_vbat_range_v"),
        ('"3.9-4.1"', r"calibration\.thrust_vbat_range_v = '3\.9-4\.1'"),
    ):
        path.write_text(f"[calibration]\nthrust_vbat_range_v = {bad}\n")
        with pytest.raises(ConfigError, match=needle) as info:
            load_settings(path, use_env=False)
        assert "\n" not in str(info.value)
