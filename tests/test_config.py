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


@pytest.mark.parametrize(
    ("text", "message"),
    [
        (
            "[tether]\nlength_m = 160\n",
            "invalid configuration: tether.length_m = 160: 160 m is outside a micro drone's "
            "0.1-30 m; centimetres? 160 cm is length_m = 1.6 (for an unusual rig set [drone] "
            "unusual_rig = true)",
        ),
        (
            "[drone]\nmass_kg = 30\n",
            "invalid configuration: drone.mass_kg = 30: 30 kg is outside a micro drone's "
            "0.005-2 kg; grams? 30 g is mass_kg = 0.03 (for an unusual rig set [drone] "
            "unusual_rig = true)",
        ),
    ],
)
def test_units_mistakes_are_refused_in_one_line(tmp_path: Path, text: str, message: str) -> None:
    """160 (cm) for the tether once ran and reported radial_m 158.3; 30 (g) for the
    mass was accepted. The message has the value and the likely unit mistake, one line."""
    cfg = tmp_path / "units.toml"
    cfg.write_text(text)
    with pytest.raises(ConfigError) as info:
        load_settings(cfg, use_env=False)
    assert str(info.value) == message
    assert "\n" not in str(info.value)


@pytest.mark.parametrize(
    ("key", "value", "needle"),
    [
        ("tether.length_m", 1600, "millimetres? 1600 mm is length_m = 1.6"),
        ("tether.weight_n_per_m", 5, "grams per metre? 5 g/m is weight_n_per_m = 0.049"),
        ("drone.mass_kg", 0.001, "0.001 kg is outside a micro drone's 0.005-2 kg (for"),
        ("tether.length_m", 0.05, "0.05 m is outside a micro drone's 0.1-30 m (for"),
    ],
)
def test_other_implausible_values(key: str, value: float, needle: str) -> None:
    table, name = key.split(".")
    with pytest.raises(ConfigError) as info:
        load_settings(None, {table: {name: value}}, use_env=False)
    assert f"{key} = {value:g}: " in str(info.value) and needle in str(info.value)


def test_plausible_edges_and_the_unusual_rig_override(tmp_path: Path) -> None:
    ok = load_settings(None, {"drone": {"mass_kg": 2.0}, "tether": {"length_m": 30}}, use_env=False)
    assert ok.drone.mass_kg == 2.0 and ok.tether.length_m == 30.0
    cfg = tmp_path / "big.toml"
    cfg.write_text("[drone]\nmass_kg = 30\nunusual_rig = true\n[tether]\nlength_m = 160\n")
    s = load_settings(cfg, use_env=False)
    assert s.drone.mass_kg == 30.0 and s.tether.length_m == 160.0
    # Per drone: the override's value and the override's own switch.
    with pytest.raises(
        ConfigError, match=r"^invalid configuration: drones\.cf2\.tether\.length_m = 160: "
    ):
        load_settings(None, {"drones": {"cf2": {"tether": {"length_m": 160}}}}, use_env=False)
    s = load_settings(
        None,
        {"drones": {"cf2": {"tether": {"length_m": 160}, "drone": {"unusual_rig": True}}}},
        use_env=False,
    )
    assert s.for_drone("cf2").tether.length_m == 160.0


@pytest.mark.parametrize(
    ("var", "needle"),
    [
        (
            "GROUNDSTATION_TEHTER__LENGTH_M",
            "GROUNDSTATION_TEHTER__LENGTH_M: unknown section 'tehter'; did you mean 'tether'?",
        ),
        (
            "GROUNDSTATION_TETHER__LENTGH_M",
            "unknown key of [tether] 'lentgh_m'; did you mean 'length_m'?",
        ),
        (
            "GROUNDSTATION_DRONES__CF2__TEHTER__LENGTH_M",
            "unknown per-drone table 'tehter'; did you mean 'tether'?",
        ),
        ("GROUNDSTATION_TETHER", "not of the form GROUNDSTATION_SECTION__KEY"),
    ],
)
def test_a_misspelt_environment_variable_is_an_error(
    monkeypatch: pytest.MonkeyPatch, var: str, needle: str
) -> None:
    """As a misspelt key in a file is: pydantic-settings drops an unknown section silently."""
    monkeypatch.setenv(var, "2.0")
    with pytest.raises(ConfigError) as info:
        load_settings(None)
    assert needle in str(info.value) and "\n" not in str(info.value)
    # use_env=False reads no variable, so none is judged
    assert load_settings(None, use_env=False).tether.length_m == 1.6


def test_known_environment_variables_still_apply(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("GROUNDSTATION_PUBLIC_CONTRACT", "/nowhere")  # the contract test's own
    monkeypatch.setenv("groundstation_tether__length_m", "2.0")  # case-insensitive, as read
    monkeypatch.setenv("GROUNDSTATION_DRONES__CF2__TETHER__LENGTH_M", "2.5")
    s = load_settings(None)
    assert s.tether.length_m == 2.0 and s.for_drone("cf2").tether.length_m == 2.5


@pytest.mark.parametrize(
    ("text", "needle"),
    [
        (
            "[base]\nposition_m = [0, 0, 75.4]\n",
            "base.position_m = [0.0, 0.0, 75.4]: further than 30 m from the origin, beyond any "
            "micro drone's tether; centimetres? [0.0, 0.0, 75.4] cm is position_m = [0, 0, "
            "0.754]",
        ),
        (
            "[base]\nposition_m = [0, 0, 0.754]\nfloor_z_m = 1.0\n",
            "base.floor_z_m = 1: above the base exit point (base.position_m z = 0.754 m)",
        ),
        (
            "[follow]\nthreshold_n = 100\n",
            "follow.threshold_n = 100: above the drone's weight (0.294 N for drone.mass_kg = "
            "0.03), a pull no micro drone resists; millinewtons? 100 mN is threshold_n = 0.1",
        ),
        (
            "[drones.cf2.follow]\nthreshold_n = 5\n",
            "drones.cf2.follow.threshold_n = 5: above the drone's weight",
        ),
        (
            "[calibration]\nthrust_axis_rad = [2.0, 0]\n",
            "within ±0.35 rad (20°); degrees? [2.0, 0.0] degrees is thrust_axis_rad = [0.03491, 0]",
        ),
    ],
)
def test_more_unit_mistakes_are_refused_with_a_hint(tmp_path: Path, text: str, needle: str) -> None:
    cfg = tmp_path / "rig.toml"
    cfg.write_text(text)
    with pytest.raises(ConfigError) as info:
        load_settings(cfg, use_env=False)
    assert needle in str(info.value) and "\n" not in str(info.value), str(info.value)
    if "thrust_axis" not in text:  # a plausibility rule: an unusual rig may say so
        cfg.write_text("[drone]\nunusual_rig = true\n" + text)
        load_settings(cfg, use_env=False)
