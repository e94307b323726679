"""The Crazyflie bridge without a drone: its logic, and the runner against the fake link."""

from __future__ import annotations

import itertools
import json
import logging
import math
import threading
import time
from collections.abc import Callable, Iterator
from typing import Any

import numpy as np
import pytest

from groundstation.bridges.crazyflie.bridge import (
    ACC,
    ATTITUDE,
    G_MPS2,
    GYRO,
    MAX_BLOCK_BYTES,
    Aligned,
    Aligner,
    CommandGate,
    MissingVariables,
    MocapPose,
    Skip,
    build_telemetry,
    plan_blocks,
    plan_variables,
    thrust_n,
    yaw_deg_from_quat,
)
from groundstation.bridges.crazyflie.fake import FAKE_TOC, FIRMWARE_TOCS, FakeLink, pwm_for_thrust
from groundstation.bridges.crazyflie.link import TYPE_SIZES
from groundstation.bridges.crazyflie.runner import CrazyflieBridge
from groundstation.bus import InMemoryBus, Sample
from groundstation.config import ConfigError, CrazyflieSection, load_settings
from groundstation.messages import Telemetry

DEFAULT_MAP = (2.130295e-11, 1.032633e-6, 5.484560e-4)


# --------------------------------------------------------------------------- thrust, config


def test_thrust_map_sums_motors_and_zero_pwm_is_zero_thrust() -> None:
    a, b, c = DEFAULT_MAP
    pwm = 40000.0
    one = a * pwm**2 + b * pwm + c
    assert thrust_n([pwm] * 4, DEFAULT_MAP) == pytest.approx(4 * one, rel=1e-12)
    assert thrust_n([pwm, pwm, 0.0, 0.0], DEFAULT_MAP) == pytest.approx(2 * one, rel=1e-12)
    assert thrust_n([0.0] * 4, DEFAULT_MAP) == 0.0
    # The default map: a 30 g drone hovers near pwm 39 000 (widely reported for a CF2.x).
    hover = pwm_for_thrust(0.030 * 9.81 / 4, DEFAULT_MAP)
    assert 35000 < hover < 43000
    assert thrust_n([hover] * 4, DEFAULT_MAP) == pytest.approx(0.030 * 9.81, rel=1e-9)


def test_the_firmware_cubic_thrust_model_in_the_motor_voltage() -> None:
    """The firmware's model (VMOTOR2THRUST0..3 of platform_defaults_cf2.h, 2.1+ propellers):
    per motor f = c0 + c1·v + c2·v² + c3·v³ with v = vbat·m/65535, summed."""
    from groundstation.bridges.crazyflie.bridge import VMOTOR2THRUST, thrust_cubic_n

    c = VMOTOR2THRUST["cubic_21plus"]
    assert c == (
        -0.02476537915958403,
        0.06523793527519485,
        -0.026792504967750107,
        0.006776789303971145,
    )
    v = 3.5 * 40000 / 65535
    one = c[0] + c[1] * v + c[2] * v**2 + c[3] * v**3
    assert thrust_cubic_n([40000.0] * 4, 3.5, c) == pytest.approx(4 * one, rel=1e-12)
    assert thrust_cubic_n([40000.0, 0.0, 0.0, 0.0], 3.5, c) == pytest.approx(one, rel=1e-12)
    assert thrust_cubic_n([0.0] * 4, 3.5, c) == 0.0
    # the same motor value gives more thrust from a fuller battery (the duty is compensated)
    assert thrust_cubic_n([40000.0] * 4, 4.1, c) > thrust_cubic_n([40000.0] * 4, 3.5, c)
    # the configuration picks it; the plan then needs pm.vbat, and a period without it is
    # skipped rather than published with a made-up thrust
    section = CrazyflieSection(thrust_model="cubic_21plus")
    no_vbat = {k: v for k, v in FAKE_TOC.items() if k != "pm.vbat"}
    with pytest.raises(MissingVariables, match=r"pm\.vbat"):
        plan_variables(section, no_vbat, "x")
    plan = plan_variables(section, FAKE_TOC, "x")
    values = {**_values(), **{m: 40000.0 for m in plan.motors}}
    tel = build_telemetry(Aligned(0, values), plan, section, 0, {"pm.vbat": 3.5}, None, 0.0)
    assert tel.thrust_n == pytest.approx(4 * one, rel=1e-6)
    with pytest.raises(Skip, match="no_vbat"):
        build_telemetry(Aligned(0, values), plan, section, 0, {}, None, 0.0)


def test_crazyflie_config_defaults_and_errors() -> None:
    section = load_settings(None, use_env=False).crazyflie
    assert section.thrust_map == DEFAULT_MAP
    assert section.log_period_ms == 10
    assert CrazyflieSection(rate_hz=33).log_period_ms == 30
    with pytest.raises(ConfigError, match=r"crazyflie.slow_period_ms = 15"):
        load_settings(None, {"crazyflie": {"slow_period_ms": 15}}, use_env=False)
    with pytest.raises(ConfigError, match=r"crazyflie.thrust_map"):
        load_settings(None, {"crazyflie": {"thrust_map": [0.0, 0.0, -1.0]}}, use_env=False)
    with pytest.raises(ConfigError, match=r"crazyflie.motor_variables = 'm'"):
        load_settings(None, {"crazyflie": {"motor_variables": "m"}}, use_env=False)


# --------------------------------------------------------------------------- log blocks


def _block_bytes(block: Any) -> int:
    return sum(TYPE_SIZES[t] for t in block.fetch_as)


@pytest.mark.parametrize(
    ("firmware", "motor_variables"), [("current", "motor"), ("2022", "motor"), ("2022", "pwm")]
)
def test_blocks_fit_one_packet_and_carry_every_variable_once(
    firmware: str, motor_variables: str
) -> None:
    section = CrazyflieSection(motor_variables=motor_variables)  # type: ignore[arg-type]
    plan = plan_variables(section, FIRMWARE_TOCS[firmware], "fake://")
    fast_vars = [v for b in plan.fast for v in b.variables]
    assert sorted(fast_vars) == sorted([*ACC, *GYRO, *ATTITUDE, *plan.motors])
    assert len(plan.fast) == 2, "acc+gyro, then attitude+motors (motors as uint16)"
    for block in (*plan.fast, *plan.slow):
        assert _block_bytes(block) <= MAX_BLOCK_BYTES
        assert block.period_ms % 10 == 0
    assert all(b.period_ms == 10 for b in plan.fast)
    assert [v for b in plan.slow for v in b.variables] == ["pm.vbat", "supervisor.info"]
    assert plan.slow[0].period_ms == 100
    motor_types = {
        t
        for b in plan.fast
        for v, t in zip(b.variables, b.fetch_as, strict=True)
        if v in plan.motors
    }
    assert motor_types == {"uint16_t"}
    # Vector components stay together.
    for group in (ACC, GYRO, ATTITUDE, plan.motors):
        assert len({b.name for b in plan.fast for v in b.variables if v in group}) == 1


def test_blocks_split_when_nothing_is_narrowed() -> None:
    toc = {f"v{i}": "float" for i in range(20)}
    blocks = plan_blocks("b", [[f"v{i}" for i in range(20)]], toc, 20)
    assert [len(b.variables) for b in blocks] == [6, 6, 6, 2]
    assert all(_block_bytes(b) <= 26 for b in blocks)
    with pytest.raises(ValueError, match="multiple of 10 ms"):
        plan_blocks("b", [["v0"]], toc, 15)


def test_missing_variables_are_all_named() -> None:
    toc = {
        k: v for k, v in FIRMWARE_TOCS["2022"].items() if k not in ("stateEstimate.qw", "motor.m3")
    }
    with pytest.raises(MissingVariables) as info:
        plan_variables(CrazyflieSection(), toc, "radio://0/80/2M")
    msg = str(info.value)
    assert "stateEstimate.qw" in msg and "motor.m3" in msg and "radio://0/80/2M" in msg
    assert info.value.missing == ("stateEstimate.qw", "motor.m3")
    # The attitude from motion capture needs no stateEstimate; pwm.* replace motor.*.
    plan = plan_variables(
        CrazyflieSection(attitude_source="mocap", motor_variables="pwm"), toc, "x"
    )
    assert plan.attitude == ()
    # armed: 'auto' goes without supervisor.info, 'supervisor' insists on it.
    no_sup = {k: v for k, v in FAKE_TOC.items() if k != "supervisor.info"}
    assert not plan_variables(CrazyflieSection(), no_sup, "x").armed
    with pytest.raises(MissingVariables, match=r"supervisor\.info"):
        plan_variables(CrazyflieSection(armed_source="supervisor"), no_sup, "x")


def test_the_default_configuration_fits_current_firmware_which_has_no_pwm_group() -> None:
    """Current firmware logs motor.m1..m4 after its battery compensation and no pwm group;
    firmware of about 2021-2022 logs both. The default (``motor``) works on both; ``pwm`` on
    current firmware fails, naming the variables and what to choose instead."""
    current, older = FIRMWARE_TOCS["current"], FIRMWARE_TOCS["2022"]
    assert not any(k.startswith("pwm.") for k in current)
    assert all(f"pwm.m{i}_pwm" in older for i in range(1, 5))
    assert current == FAKE_TOC, "the fake plays current firmware unless told otherwise"
    for toc in (current, older):
        plan = plan_variables(CrazyflieSection(), toc, "x")
        assert plan.motors == ("motor.m1", "motor.m2", "motor.m3", "motor.m4")
        assert plan.not_logged == ()
    with pytest.raises(MissingVariables) as info:
        plan_variables(CrazyflieSection(motor_variables="pwm"), current, "radio://0/80/2M")
    msg = str(info.value)
    assert "pwm.m1_pwm" in msg and "pwm.m4_pwm" in msg
    assert 'motor_variables = "motor"' in msg and "thrust_vbat_slope_per_v" in msg


# --------------------------------------------------------------------------- alignment


def test_aligner_joins_blocks_by_timestamp_with_a_phase_offset() -> None:
    al = Aligner(["a", "b"], period_ms=10)
    assert al.push("a", 1000, {"x": 1.0}) == []  # b not yet here
    out = al.push("b", 1003, {"y": 2.0})
    assert out == [Aligned(1000, {"x": 1.0, "y": 2.0})]
    # b arrives first in the next period: fine too.
    assert al.push("b", 1013, {"y": 3.0}) == []
    assert al.push("a", 1010, {"x": 4.0}) == [Aligned(1010, {"x": 4.0, "y": 3.0})]


def test_aligner_drops_out_of_order_and_unmatched_samples() -> None:
    al = Aligner(["a", "b"], period_ms=10)
    al.push("a", 1000, {"x": 1.0})
    al.push("b", 1002, {"y": 1.0})
    # an old timestamp replayed: dropped, counted
    assert al.push("a", 990, {"x": 9.0}) == []
    assert al.push("a", 1000, {"x": 9.0}) == []
    assert al.out_of_order == 2
    # a's sample of 1010 is lost: b's 1012 is orphaned, then 1020 pairs
    assert al.push("b", 1012, {"y": 2.0}) == []
    assert al.push("a", 1020, {"x": 3.0}) == []
    assert al.push("b", 1022, {"y": 3.0}) == [Aligned(1020, {"x": 3.0, "y": 3.0})]
    assert al.unmatched == 1
    # b's sample of 1030 is lost: a's 1030 is dropped once b shows 1040
    al.push("a", 1030, {"x": 4.0})
    assert al.push("b", 1042, {"y": 5.0}) == []
    assert al.push("a", 1040, {"x": 5.0}) == [Aligned(1040, {"x": 5.0, "y": 5.0})]
    assert al.unmatched == 2


def test_aligner_unwraps_the_24_bit_clock() -> None:
    al = Aligner(["a"], period_ms=10)
    wrap = 1 << 24
    assert al.push("a", wrap - 10, {})[0].stamp_ms == wrap - 10
    assert al.push("a", 0, {})[0].stamp_ms == wrap
    assert al.push("a", 10, {})[0].stamp_ms == wrap + 10


# --------------------------------------------------------------------------- units


def _values(**over: float) -> dict[str, float]:
    v = {k: 0.0 for k in (*ACC, *GYRO, *ATTITUDE, "motor.m1", "motor.m2", "motor.m3", "motor.m4")}
    v.update({"acc.z": 1.0, "stateEstimate.qw": 1.0})
    v.update({f"motor.m{i}": 40000.0 for i in range(1, 5)})
    for k, x in over.items():
        v[k.replace("__", ".")] = x
    return v


def test_telemetry_is_si() -> None:
    section = CrazyflieSection()
    plan = plan_variables(section, FAKE_TOC, "x")
    values = _values(acc__x=0.1, gyro__z=180.0, stateEstimate__qw=1.2)  # quat not unit
    slow = {"pm.vbat": 3.7, "supervisor.info": 0b0011}
    tel = build_telemetry(Aligned(12345, values), plan, section, 7, slow, None, 0.0)
    assert isinstance(tel, Telemetry)
    assert tel.seq == 7 and tel.stamp_s == pytest.approx(12.345)
    assert tel.accel_mps2 == pytest.approx((0.1 * G_MPS2, 0.0, G_MPS2))
    assert tel.gyro_rps == pytest.approx((0.0, 0.0, math.pi))
    assert tel.quat_wxyz == pytest.approx((1.0, 0.0, 0.0, 0.0))
    assert tel.thrust_n == pytest.approx(thrust_n([40000.0] * 4, DEFAULT_MAP))
    assert tel.vbat_v == 3.7 and tel.armed is True and tel.position_m is None
    disarmed = build_telemetry(
        Aligned(0, values), plan, section, 0, {"supervisor.info": 0b0001}, None, 0.0
    )
    assert disarmed.armed is False
    with pytest.raises(Skip) as info:
        build_telemetry(Aligned(0, _values(acc__y=math.nan)), plan, section, 0, {}, None, 0.0)
    assert info.value.kind == "bad_reading"


def test_mocap_position_and_attitude() -> None:
    section = CrazyflieSection(attitude_source="mocap", mocap_stale_s=0.1)
    plan = plan_variables(section, FAKE_TOC, "x")
    quat = (math.cos(0.5), 0.0, 0.0, math.sin(0.5))  # yaw 1 rad
    pose = MocapPose((0.3, -0.2, 0.5), quat, received_s=10.0)
    tel = build_telemetry(Aligned(0, _values()), plan, section, 0, {}, pose, 10.05)
    assert tel.position_m == (0.3, -0.2, 0.5)
    assert tel.quat_wxyz == pytest.approx(quat)
    assert tel.attitude_source == "external", "the estimator must know the frame is not the IMU's"
    assert yaw_deg_from_quat(tel.quat_wxyz) == pytest.approx(math.degrees(1.0))
    zero = MocapPose((0.3, -0.2, 0.5), (0.0, 0.0, 0.0, 0.0), received_s=10.0)
    with pytest.raises(Skip, match="bad_reading"):
        build_telemetry(Aligned(0, _values()), plan, section, 0, {}, zero, 10.05)
    with pytest.raises(Skip, match="no_attitude"):  # stale pose: no attitude at all
        build_telemetry(Aligned(0, _values()), plan, section, 0, {}, pose, 10.2)
    est = CrazyflieSection(attitude_source="estimator")
    tel = build_telemetry(
        Aligned(0, _values()), plan_variables(est, FAKE_TOC, "x"), est, 0, {}, pose, 10.2
    )
    assert tel.position_m is None, "a stale motion-capture position is left out"
    assert tel.attitude_source == "onboard"


# --------------------------------------------------------------------------- command gate


def test_gate_sends_nothing_until_asked_then_holds_the_last_setpoint() -> None:
    gate = CommandGate(watchdog_s=0.5, silence_s=0.5, hold_s=5.0)
    assert gate.tick(0.0) is None and gate.phase(0.0) == "idle"
    assert gate.on_setpoint((0.1, 0.2, 0.5), 10.0, 0.0, 10.0, 30.0) == "accepted"
    cmd = gate.tick(0.01)
    assert cmd is not None and cmd.position_m == (0.1, 0.2, 0.5) and cmd.yaw_deg == 30.0
    assert not gate.holding(0.4) and gate.phase(0.4) == "flying"
    assert gate.holding(0.6)
    held = gate.tick(5.0)
    assert held is not None and held.position_m == (0.1, 0.2, 0.5), "hold, do not extrapolate"
    # fresh again
    assert gate.on_setpoint((0.2, 0.2, 0.5), 10.5, 5.1, 10.5, 90.0) == "accepted"
    again = gate.tick(5.1)
    assert again is not None and again.position_m == (0.2, 0.2, 0.5)
    assert again.yaw_deg == 30.0, "the yaw of the first setpoint is held"
    # the ground station heard (an Estimate) with no new setpoint: flying, not holding
    gate.heard_s = 8.0
    assert gate.phase(8.2) == "flying" and gate.phase(8.6) == "holding"


def test_gate_holds_then_lands_on_ground_station_silence() -> None:
    """Silence 0.1 s: hold; 0.3 s more: straight down at 0.25 m/s, 0.5 s on the floor, motors
    off. Setpoints arriving during the landing do not lift the drone again."""
    from groundstation.bridges.crazyflie.bridge import LAND_SETTLE_S

    gate = CommandGate(watchdog_s=0.5, silence_s=0.1, hold_s=0.3, land_speed_mps=0.25)
    assert gate.on_setpoint((0.1, 0.2, 0.5), 10.0, 0.0, 10.0, 0.0) == "accepted"
    assert gate.phase(0.05) == "flying" and gate.phase(0.15) == "holding"
    held = gate.tick(0.39)
    assert held is not None and held.position_m == (0.1, 0.2, 0.5) and gate.phase(0.39) == "holding"
    start = gate.tick(0.41)
    assert start is not None and gate.phase(0.41) == "landing"
    assert "silent" in gate.landing_reason
    assert start.position_m == pytest.approx((0.1, 0.2, 0.5), abs=1e-9)
    mid = gate.tick(1.41)
    assert mid is not None and mid.position_m == pytest.approx((0.1, 0.2, 0.25))
    assert gate.on_setpoint((0.1, 0.2, 0.6), 10.2, 1.42, 10.2, 0.0) == "landing"
    floor = gate.tick(2.41)
    assert floor is not None and not floor.motors_off and floor.position_m[2] == pytest.approx(0)
    off = gate.tick(2.42 + LAND_SETTLE_S)
    assert off is not None and off.motors_off
    assert gate.tick(2.5 + LAND_SETTLE_S) is None and gate.phase(3.0) == "idle"
    assert not gate.latched, "a landing does not latch"
    assert gate.dropped == {"landing": 1}


def test_gate_drops_stale_setpoints() -> None:
    gate = CommandGate(watchdog_s=0.5)
    # computed from telemetry 0.8 s older than the latest: stale
    assert gate.on_setpoint((0.0, 0.0, 0.5), 9.2, 0.0, 10.0, 0.0) == "stale"
    assert gate.tick(0.0) is None
    assert gate.on_setpoint((0.0, 0.0, 0.5), 10.0, 0.0, 10.0, 0.0) == "accepted"
    assert gate.on_setpoint((9.0, 0.0, 0.5), 9.9, 0.0, 10.0, 0.0) == "stale", "stamp backwards"
    assert gate.on_setpoint((math.nan, 0.0, 0.5), 10.1, 0.0, 10.1, 0.0) == "bad"
    assert gate.on_setpoint((9.0, 0.0, 0.5), 1.7e9, 0.0, 10.1, 0.0) == "clock", "wall clock"
    assert gate.on_setpoint((9.0, 0.0, 0.5), 10.2, 0.0, None, 0.0) == "stale", "no telemetry"
    cmd = gate.tick(0.0)
    assert cmd is not None and cmd.position_m == (0.0, 0.0, 0.5)
    assert gate.dropped == {"stale": 3, "bad": 1, "clock": 1}


def test_gate_latches_on_stop_until_rearm_and_forgets_on_link_loss() -> None:
    gate = CommandGate(watchdog_s=0.5, yaw_deg=0.0)
    gate.on_setpoint((0.0, 0.0, 0.5), 1.0, 0.0, 1.0, None)
    gate.on_stop("tug-to-land")
    assert gate.latched and gate.tick(0.1) is None
    assert gate.on_setpoint((0.0, 0.0, 0.5), 1.1, 0.1, 1.1, None) == "latched"
    assert gate.tick(0.2) is None
    gate.rearm()
    assert gate.tick(0.3) is None, "re-arming sends nothing by itself"
    assert gate.on_setpoint((0.0, 0.0, 0.6), 1.2, 0.3, 1.2, None) == "accepted"
    assert gate.tick(0.3) is not None
    gate.on_link_lost()
    assert gate.tick(0.4) is None, "after a reconnection a fresh setpoint is needed"


def test_gate_ramps_take_off_and_land_then_motors_off() -> None:
    from groundstation.bridges.crazyflie.bridge import LAND_SETTLE_S

    gate = CommandGate(watchdog_s=0.5)
    assert gate.ramp((0.3, 0.0, 0.0), (0.3, 0.0, 0.5), 0.25, 10.0, 45.0) == "accepted"
    gate.heard_s = 11.0  # the ground station's heartbeat (Estimates)
    mid = gate.tick(11.0)
    assert mid is not None and mid.position_m == pytest.approx((0.3, 0.0, 0.25))
    assert mid.yaw_deg == 45.0
    gate.heard_s = 20.0
    top = gate.tick(20.0)
    assert top is not None and top.position_m == pytest.approx((0.3, 0.0, 0.5))
    assert not gate.holding(20.0), "heard: flying"
    assert gate.holding(20.2), "a ramp is no heartbeat: silent, the drone holds"
    start = gate.position_in_force(20.0)
    assert start is not None
    assert gate.ramp(start, (0.3, 0.0, 0.0), 0.5, 20.0, 0.0, land=True) == "accepted"
    down = gate.tick(21.0 + LAND_SETTLE_S / 2)
    assert down is not None and not down.motors_off and down.position_m[2] == pytest.approx(0.0)
    off = gate.tick(21.0 + 2 * LAND_SETTLE_S)
    assert off is not None and off.motors_off
    assert gate.tick(22.0) is None, "after landing nothing is sent"
    gate.on_stop("x")
    assert gate.ramp((0, 0, 0), (0, 0, 0.5), 0.25, 30.0, 0.0) == "latched"
    gate.rearm()
    assert gate.ramp((0, 0, 0), (0, 0, 0.5), 5.0, 30.0, 0.0) == "bad", "too fast"


def test_gate_refuses_setpoints_out_of_reach_or_too_fast() -> None:
    from groundstation.bridges.crazyflie.bridge import Reach

    reach = Reach((0.0, 0.0, 0.754), 1.6, 0.05)
    gate = CommandGate(watchdog_s=0.5, reach=reach, max_speed_mps=1.0, yaw_deg=0.0)
    assert gate.on_setpoint((50.0, 0.0, 10.0), 1.0, 0.0, 1.0, None) == "out_of_reach"
    assert gate.on_setpoint((1.6, 0.0, 0.754), 1.0, 0.0, 1.0, None) == "out_of_reach"
    # a first setpoint is judged against the measured position: 0.6 m > 1 m/s x 0.5 s
    assert gate.on_setpoint((0.0, 0.0, 0.6), 1.0, 0.0, 1.0, None, (0.0, 0.0, 0.0)) == "too_fast"
    assert gate.on_setpoint((0.0, 0.0, 0.4), 1.0, 0.0, 1.0, None, (0.0, 0.0, 0.0)) == "accepted"
    # 1 cm per 10 ms is 1 m/s: accepted; 5 cm per 10 ms is not, nor after refusals
    assert gate.on_setpoint((0.01, 0.0, 0.4), 1.01, 0.01, 1.01, None) == "accepted"
    assert gate.on_setpoint((0.06, 0.0, 0.4), 1.02, 0.02, 1.02, None) == "too_fast"
    assert gate.on_setpoint((0.06, 0.0, 0.4), 1.03, 0.03, 1.03, None) == "too_fast"
    # two setpoints delivered together are judged over one setpoint period (20 ms)
    assert gate.on_setpoint((0.025, 0.0, 0.4), 1.03, 0.03, 1.03, None) == "accepted"
    # after a pause in the stream (0.5 s of drone time) a 0.4 m move is 0.8 m/s
    assert gate.on_setpoint((0.425, 0.0, 0.4), 1.53, 0.53, 1.53, None) == "accepted"
    cmd = gate.tick(0.53)
    assert cmd is not None and cmd.position_m == (0.425, 0.0, 0.4)
    assert gate.dropped == {"out_of_reach": 2, "too_fast": 3}


def test_gate_landing_stop_lands_and_emergency_stop_latches() -> None:
    from groundstation.bridges.crazyflie.bridge import LAND_SETTLE_S

    gate = CommandGate(watchdog_s=0.5, yaw_deg=0.0, land_speed_mps=0.5, hold_s=5.0)
    assert gate.on_stop("nothing flying", 0.0, landing=True) == "motors_off"
    assert not gate.latched
    gate.on_setpoint((0.0, 0.0, 0.5), 1.0, 0.0, 1.0, None)
    assert gate.on_stop("tug-to-land", 0.0, landing=True) == "landing"
    assert not gate.latched and gate.phase(0.0) == "landing"
    assert gate.on_stop("tug-to-land", 0.1, landing=True) == "landing", "a repeat changes nothing"
    half = gate.tick(0.5)
    assert half is not None and half.position_m[2] == pytest.approx(0.25)
    off = gate.tick(1.0 + LAND_SETTLE_S + 0.01)
    assert off is not None and off.motors_off and not gate.latched
    # flies again without a re-arm
    assert gate.on_setpoint((0.0, 0.0, 0.5), 3.0, 3.0, 3.0, None) == "accepted"
    assert gate.on_stop("operator", 3.0) == "latched" and gate.tick(3.1) is None
    assert gate.on_stop("tug-to-land", 3.2, landing=True) == "latched", "no landing lifts a latch"
    assert gate.latched


# --------------------------------------------------------------------------- runner


class Harness:
    """The runner on a thread, with an in-memory bus and the fake link driven by hand."""

    def __init__(
        self,
        link: FakeLink,
        section: CrazyflieSection | None = None,
        bus: InMemoryBus | None = None,
    ) -> None:
        self.bus = bus or InMemoryBus()
        self.link = link
        reach = ((0.0, 0.0, 0.754), 1.6)  # the default base and tether
        self.bridge = CrazyflieBridge(
            section or CrazyflieSection(), self.bus, "cf1", link, reach=reach
        )
        self.telemetry: list[dict[str, Any]] = []
        self.status: list[dict[str, Any]] = []
        self.bus.subscribe("tether/cf1/telemetry", lambda s: self.telemetry.append(_j(s)))
        self.bus.subscribe("tether/cf1/bridge", lambda s: self.status.append(_j(s)))
        self.stop = threading.Event()
        self.rc: list[int] = []
        self.thread = threading.Thread(target=lambda: self.rc.append(self.bridge.run(self.stop)))
        self.clock_ms = 1000

    def start(self) -> Harness:
        self.thread.start()
        wait_for(lambda: self.link.opens >= 1 and self.bridge.connected, "connected")
        return self

    def period(self, n: int = 1) -> None:
        """Play ``n`` periods of every block."""
        plan = self.bridge._plan
        assert plan is not None
        for _ in range(n):
            sample = self.link.values()
            # the slow block first: the bridge waits for its first sample (armed state)
            for i, block in enumerate((*plan.slow, *plan.fast)):
                values = {v: sample[v] for v in block.variables}
                self.link.emit(block.name, self.clock_ms + i, values)
            self.clock_ms += self.bridge.section.log_period_ms

    def publish(self, key: str, payload: dict[str, Any]) -> None:
        self.bus.publish(key, json.dumps(payload).encode())

    def close(self) -> int:
        self.stop.set()
        self.thread.join(5.0)
        assert not self.thread.is_alive()
        self.bus.close()
        return self.rc[0]


def _j(sample: Sample) -> dict[str, Any]:
    return dict(json.loads(sample.payload))


def wait_for(predicate: Callable[[], bool], what: str, timeout_s: float = 5.0) -> None:
    deadline = time.monotonic() + timeout_s
    done = threading.Event()
    while not predicate():
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout_s} s waiting for {what}")
        done.wait(0.005)


@pytest.fixture
def harness() -> Iterator[Callable[..., Harness]]:
    made: list[Harness] = []

    def make(
        link: FakeLink | None = None, bus: InMemoryBus | None = None, **section: Any
    ) -> Harness:
        section.setdefault("data_timeout_s", 60.0)  # tests pause between packets
        section.setdefault("silence_s", 60.0)  # and publish no Estimates (the heartbeat)
        h = Harness(link or FakeLink(), CrazyflieSection(**section), bus)
        made.append(h)
        return h.start()

    yield make
    for h in made:
        if h.thread.is_alive():
            h.close()


def _names(link: FakeLink) -> list[str]:
    return [name for name, _ in link.commands]


def test_runner_publishes_si_telemetry_with_increasing_seq(harness: Any) -> None:
    h = harness()
    h.period(50)
    wait_for(lambda: len(h.telemetry) >= 50, "50 telemetry")
    assert [t["seq"] for t in h.telemetry] == list(range(len(h.telemetry)))
    stamps = [t["stamp_s"] for t in h.telemetry]
    assert all(b - a == pytest.approx(0.010) for a, b in itertools.pairwise(stamps))
    last = h.telemetry[-1]
    assert last["accel_mps2"][2] == pytest.approx(G_MPS2, abs=0.05)
    pull_n = 0.05  # the fake's hover: thrust carries the weight and the tether's pull
    assert last["thrust_n"] == pytest.approx(0.030 * 9.81 + pull_n, rel=1e-3)
    # the fake's battery under hover load, sagging 0.01 V per flight minute
    assert last["vbat_v"] == pytest.approx(3.95, abs=0.005) and last["armed"] is True
    assert h.close() == 0
    assert _names(h.link)[-1] == "close"
    assert "send_stop_setpoint" not in _names(h.link), "never commanded: nothing to stop"


def test_runner_waits_for_the_armed_state_before_publishing(harness: Any) -> None:
    h = harness()
    plan = h.bridge._plan
    sample = h.link.values()
    for block in plan.fast:  # fast blocks only: no armed state yet
        h.link.emit(block.name, 900, {v: sample[v] for v in block.variables})
    h.period(3)
    wait_for(lambda: len(h.telemetry) >= 3, "telemetry")
    assert h.bridge.counts["before_slow_block"] == 1
    assert all(t["armed"] is True and t["stamp_s"] > 0.95 for t in h.telemetry)


def test_runner_drops_out_of_order_packets(harness: Any) -> None:
    h = harness()
    h.period(5)
    plan = h.bridge._plan
    sample = h.link.values()
    first = plan.fast[0]
    h.link.emit(first.name, h.clock_ms - 30, {v: sample[v] for v in first.variables})
    h.period(5)
    wait_for(lambda: len(h.telemetry) >= 10, "10 telemetry")
    stamps = [t["stamp_s"] for t in h.telemetry]
    assert stamps == sorted(stamps) and len(set(stamps)) == len(stamps)
    assert h.bridge._aligner is not None and h.bridge._aligner.out_of_order == 1


def test_runner_streams_setpoints_and_a_stop_latches(harness: Any) -> None:
    h = harness()
    h.period(5)
    wait_for(lambda: len(h.telemetry) >= 5, "telemetry")
    stamp = h.telemetry[-1]["stamp_s"]
    h.publish("tether/cf1/cmd/setpoint", {"stamp_s": stamp, "position_m": [0.1, 0.0, 0.5]})
    wait_for(lambda: _names(h.link).count("send_position_setpoint") >= 5, "streamed setpoints")
    sent = [a for n, a in h.link.commands if n == "send_position_setpoint"]
    assert all(a[:3] == (0.1, 0.0, 0.5) for a in sent)
    h.publish("tether/cf1/cmd/stop", {"stamp_s": stamp, "reason": "tug-to-land"})
    wait_for(lambda: "stop_motors" in _names(h.link), "stop_motors")
    h.publish("tether/cf1/cmd/setpoint", {"stamp_s": stamp + 0.01, "position_m": [0.2, 0, 0.5]})
    wait_for(lambda: h.bridge.counts.get("setpoint_latched", 0) == 1, "latched setpoint dropped")
    names = _names(h.link)
    i_stop = names.index("stop_motors")
    assert names.count("stop_motors") == 1
    assert "send_position_setpoint" not in names[i_stop:], "no setpoint after a Stop"
    wait_for(lambda: any(s["latched"] for s in h.status), "status says latched")
    # the operator re-arms; the next setpoint flies again
    h.publish("tether/cf1/cmd/rearm", {})
    wait_for(lambda: "arm" in _names(h.link), "the arming request")
    h.publish("tether/cf1/cmd/setpoint", {"stamp_s": stamp + 0.02, "position_m": [0.3, 0, 0.5]})
    wait_for(
        lambda: any(n == "send_position_setpoint" and a[0] == 0.3 for n, a in h.link.commands),
        "setpoint after rearm",
    )
    assert h.close() == 0
    assert _names(h.link)[-2:] == ["send_stop_setpoint", "close"], "shutdown stops setpoints"


def test_runner_reconnects_after_a_dropped_link_and_logs_once(
    harness: Any, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.WARNING, logger="groundstation.crazyflie")
    h = harness()
    h.period(5)
    wait_for(lambda: len(h.telemetry) >= 5, "telemetry")
    stamp = h.telemetry[-1]["stamp_s"]
    h.publish("tether/cf1/cmd/setpoint", {"stamp_s": stamp, "position_m": [0.1, 0.0, 0.5]})
    wait_for(lambda: "send_position_setpoint" in _names(h.link), "a setpoint")
    h.link.lose()
    wait_for(lambda: h.link.opens >= 2 and h.bridge.connected, "reconnected")
    n_before = len(h.telemetry)
    h.period(5)
    wait_for(lambda: len(h.telemetry) >= n_before + 5, "telemetry after reconnecting")
    seqs = [t["seq"] for t in h.telemetry]
    assert seqs == list(range(len(seqs))), "seq continues across the reconnection"
    lost_logs = [r for r in caplog.records if "lost" in r.getMessage()]
    assert len(lost_logs) == 1
    names = _names(h.link)
    i_lost = names.index("lost")
    assert "send_position_setpoint" not in names[i_lost:], "no held setpoint after a loss"


def test_runner_takes_silence_as_a_lost_link(harness: Any) -> None:
    h = harness(data_timeout_s=0.2)
    h.period(3)
    wait_for(lambda: len(h.telemetry) >= 3, "telemetry")
    # no more packets: after 0.2 s the bridge gives the link up and opens it again
    wait_for(lambda: h.link.opens >= 2, "reopened after silence")
    assert h.bridge.counts.get("link_lost", 0) >= 1


def test_runner_stop_while_disconnected_is_sent_at_reconnection(harness: Any) -> None:
    link = FakeLink("fake://hover?down_s=0.3")
    h = harness(link)
    h.period(3)
    link._down_until = time.monotonic() + 0.3  # refuse reconnecting for a while
    link.lose()
    wait_for(lambda: not h.bridge.connected, "disconnected")
    h.publish("tether/cf1/cmd/stop", {"stamp_s": 0.0, "reason": "operator"})
    wait_for(lambda: h.bridge.connected and "stop_motors" in _names(link), "stop on reconnect")
    names = _names(link)
    assert names.index("stop_motors") > names.index("start_logging", names.index("lost"))
    assert h.bridge.gate.latched


def test_runner_fails_clearly_on_missing_variables(caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.ERROR, logger="groundstation.crazyflie")
    link = FakeLink("fake://hover?missing=stateEstimate.qx,acc.z")
    bus = InMemoryBus()
    try:
        rc = CrazyflieBridge(CrazyflieSection(), bus, "cf1", link).run(threading.Event())
    finally:
        bus.close()
    assert rc == 2
    msg = " ".join(r.getMessage() for r in caplog.records)
    assert "acc.z" in msg and "stateEstimate.qx" in msg
    assert _names(link) == ["open", "close"]


def test_runner_attaches_mocap_position_and_forwards_extpos(harness: Any) -> None:
    h = harness(mocap_key="mocap/{drone}", send_extpos=True, mocap_stale_s=5.0)
    h.publish("mocap/cf1", {"position_m": [0.3, 0.1, 0.5]})
    wait_for(lambda: "send_extpos" in _names(h.link), "extpos forwarded")
    h.period(3)
    wait_for(lambda: len(h.telemetry) >= 3, "telemetry")
    assert h.telemetry[-1]["position_m"] == [0.3, 0.1, 0.5]
    h.publish("mocap/cf1", {"position_m": [0.3, "x", 0.5]})
    wait_for(lambda: h.bridge.counts.get("bad_input", 0) == 1, "bad pose counted")


# --------------------------------------------------------------------------- CflibLink


class _RecordingDriver:
    """Stands in for cflib's radio driver below a real ``Crazyflie``: records packets, and
    answers log block creation and start as the firmware does (error ``refuse_errno`` for
    the creation of a block holding a variable of ``refuse``; nothing when not ``answers``)."""

    needs_resending = False

    def __init__(self) -> None:
        self.sent: list[tuple[int, int, bytes]] = []
        self.cf: Any = None
        self.refuse: set[int] = set()
        """TOC ids whose blocks the creation refuses."""
        self.refuse_errno = 12  # ENOMEM
        self.answers = True

    def send_packet(self, pk: Any) -> None:
        data = bytes(pk.data)
        self.sent.append((pk.port, pk.channel, data))
        if self.answers and pk.port == 5 and pk.channel == 1 and data[0] in (0, 6, 3):
            # create (v1, v2) or start
            ids: set[int] = set()
            if data[0] == 0:  # v1 create: (type, id) per variable
                ids = {data[i + 1] for i in range(2, len(data), 2)}
            elif data[0] == 6:  # v2 create: (type, id_lo, id_hi) per variable
                ids = {data[i + 1] | data[i + 2] << 8 for i in range(2, len(data), 3)}
            error = self.refuse_errno if ids & self.refuse else 0
            # Answer from another thread, as the radio's reader does: cflib sends the start
            # from inside its answer handler, under the send lock held here.
            answer = threading.Thread(target=self._answer, args=(data[0], data[1], error))
            answer.daemon = True
            answer.start()

    def _answer(self, cmd: int, block_id: int, error: int) -> None:
        from cflib.crtp.crtpstack import CRTPPacket

        pk = CRTPPacket()
        pk.set_header(5, 1)
        pk.data = bytes([cmd, block_id, error])
        self.cf.log._new_packet_cb(pk)

    def close(self) -> None:
        pass


def _cflib_link(toc: dict[str, str]) -> tuple[Any, Any, _RecordingDriver]:
    """A :class:`CflibLink` on a real cflib ``Crazyflie`` whose TOC is ``toc``."""
    from cflib.crazyflie import Crazyflie
    from cflib.crazyflie.log import LogTocElement
    from cflib.crazyflie.toc import Toc

    from groundstation.bridges.crazyflie.link import CflibLink

    cf = Crazyflie()
    driver = _RecordingDriver()
    driver.cf = cf
    cf.link = driver
    cf.platform._protocolVersion = 12  # a firmware with the supervisor port
    type_ids = {v[0]: k for k, v in LogTocElement.types.items()}
    table = Toc()
    for ident, (name, ctype) in enumerate(toc.items()):
        group, var = name.split(".")
        data = bytearray([type_ids[ctype]]) + group.encode() + b"\0" + var.encode() + b"\0"
        table.add_element(LogTocElement(ident, data))
    cf.log.toc = table
    link = CflibLink("radio://0/80/2M/E7E7E7E7E7")
    link._cf = cf
    return link, cf, driver


def test_cflib_accepts_the_planned_blocks_and_decodes_their_packets() -> None:
    import struct

    from cflib.crtp.crtpstack import CRTPPacket, CRTPPort

    link, cf, driver = _cflib_link(dict(FAKE_TOC))
    plan = plan_variables(CrazyflieSection(), FAKE_TOC, link.uri)
    got: list[tuple[str, int, dict[str, float]]] = []
    link.start_logging([*plan.fast, *plan.slow], lambda b, t, v: got.append((b, t, dict(v))))
    creates = [p for p in driver.sent if p[0] == CRTPPort.LOGGING and p[2][0] in (0, 6)]
    assert len(creates) == len(plan.fast) + len(plan.slow), "one create-block per block"
    # A log packet of the attitude+motors block as the firmware sends it.
    conf = next(c for c in cf.log.log_blocks if "motor.m1" in [v.name for v in c.variables])
    fmt = {"float": "f", "uint16_t": "H"}
    block = next(b for b in plan.fast if b.name == conf.name)
    values: dict[str, float] = {v: (1.0 if v.endswith("qw") else 0.0) for v in block.variables}
    values.update({m: 41000 + i for i, m in enumerate(plan.motors)})
    body = b"".join(
        struct.pack("<" + fmt[t], values[v])
        for v, t in zip(block.variables, block.fetch_as, strict=True)
    )
    ts = 0x123456
    pk = CRTPPacket()
    pk.set_header(CRTPPort.LOGGING, 2)
    pk.data = bytes([conf.id, ts & 0xFF, (ts >> 8) & 0xFF, ts >> 16]) + body
    cf.log._new_packet_cb(pk)
    assert got == [(block.name, ts, values)]


def test_cflib_refuses_a_block_larger_than_a_packet() -> None:
    from groundstation.bridges.crazyflie.link import LinkError, LogBlock

    toc = {f"g.v{i}": "float" for i in range(7)}
    link, _, _ = _cflib_link(toc)
    big = LogBlock("big", 10, tuple(toc), ("float",) * 7)  # 28 bytes
    with pytest.raises(LinkError, match="big"):
        link.start_logging([big], lambda b, t, v: None)


def test_cflib_commands_go_out_on_the_right_ports() -> None:
    import struct

    from cflib.crtp.crtpstack import CRTPPort

    link, _, driver = _cflib_link(dict(FAKE_TOC))
    link.send_position_setpoint(0.1, 0.2, 0.5, 30.0)
    port, _, data = driver.sent[-1]
    assert port == CRTPPort.COMMANDER_GENERIC
    assert struct.unpack("<Bffff", data) == pytest.approx((7, 0.1, 0.2, 0.5, 30.0))
    driver.sent.clear()
    link.stop_motors()
    assert (CRTPPort.SUPERVISOR, 1, bytes([0x03])) in driver.sent, "supervisor emergency stop"
    assert (CRTPPort.COMMANDER_GENERIC, 0, bytes([0])) in driver.sent, "and a stop setpoint"
    driver.sent.clear()
    link.arm()
    assert driver.sent == [(CRTPPort.SUPERVISOR, 1, bytes([0x01, 1]))], "arming request"


def test_runner_takeoff_and_land_from_the_mocap_position(harness: Any) -> None:
    h = harness(mocap_key="mocap/{drone}", mocap_stale_s=5.0)
    h.period(3)
    wait_for(lambda: len(h.telemetry) >= 3, "telemetry")
    h.publish("tether/cf1/cmd/takeoff", {"height_m": 0.4})
    wait_for(lambda: h.bridge.counts.get("takeoff_refused", 0) == 1, "refused without mocap")
    assert "send_position_setpoint" not in _names(h.link)
    h.publish("mocap/cf1", {"position_m": [0.3, 0.1, 0.02]})
    h.publish("tether/cf1/cmd/takeoff", {"height_m": 2.5})  # 1.75 m above a 1.6 m tether
    wait_for(lambda: h.bridge.counts.get("takeoff_refused", 0) == 2, "refused beyond reach")
    h.publish("tether/cf1/cmd/takeoff", {"height_m": 0.4, "speed_mps": 1.0})
    wait_for(
        lambda: any(
            n == "send_position_setpoint" and a[2] == pytest.approx(0.4) for n, a in h.link.commands
        ),
        "at the take-off height",
    )
    ups = [a for n, a in h.link.commands if n == "send_position_setpoint"]
    assert all(a[:2] == pytest.approx((0.3, 0.1)) for a in ups), "straight up"
    zs = [a[2] for a in ups]
    assert zs == sorted(zs) and zs[0] < 0.1
    h.publish("tether/cf1/cmd/land", {"speed_mps": 1.0})
    wait_for(lambda: "send_stop_setpoint" in _names(h.link), "motors off after landing", 10)
    names = _names(h.link)
    i_off = names.index("send_stop_setpoint")
    downs = [a[2] for n, a in h.link.commands[:i_off] if n == "send_position_setpoint"]
    assert downs[-1] == pytest.approx(0.0)
    assert h.close() == 0
    assert "send_position_setpoint" not in _names(h.link)[i_off:]


def test_example_lab_config_loads() -> None:
    from pathlib import Path

    path = Path(__file__).resolve().parents[1] / "config" / "crazyflie.toml"
    settings = load_settings(path, use_env=False)
    assert settings.crazyflie.mocap_key == "mocap/{drone}"
    assert settings.crazyflie.thrust_map == DEFAULT_MAP


def test_a_command_failing_on_the_link_counts_as_a_loss(harness: Any) -> None:
    from groundstation.bridges.crazyflie.link import LinkError

    class Flaky(FakeLink):
        failed = False

        def send_position_setpoint(self, x_m: float, y_m: float, z_m: float, yaw: float) -> None:
            if not self.failed:
                self.failed = True
                raise LinkError("radio gone")
            super().send_position_setpoint(x_m, y_m, z_m, yaw)

    h = harness(Flaky())
    h.period(3)
    wait_for(lambda: len(h.telemetry) >= 3, "telemetry")
    stamp = h.telemetry[-1]["stamp_s"]
    h.publish("tether/cf1/cmd/setpoint", {"stamp_s": stamp, "position_m": [0.1, 0.0, 0.5]})
    wait_for(lambda: h.link.opens >= 2 and h.bridge.connected, "reconnected after the failure")
    assert h.bridge.counts["link_lost"] == 1
    assert "send_position_setpoint" not in _names(h.link), "the setpoint is forgotten"


def test_cflib_link_refuses_a_uri_it_cannot_open() -> None:
    from groundstation.bridges.crazyflie.link import CflibLink, LinkError

    with pytest.raises(LinkError, match="not a cflib URI"):
        CflibLink("radio:/0/80")
    assert CflibLink("udp://127.0.0.1:19850").uri == "udp://127.0.0.1:19850"


# ------------------------------------------------------------------ over cflib's UDP driver


@pytest.fixture
def firmware() -> Iterator[Any]:
    from tests.crtp_firmware import CrtpFirmware

    fw = CrtpFirmware(FAKE_TOC)
    yield fw
    fw.close()


def test_cflib_link_connects_over_udp_and_streams_the_planned_blocks(firmware: Any) -> None:
    """CflibLink end to end through cflib 0.1.34 (connect, TOC, blocks, data, commands) against
    a minimal CRTP responder standing in for firmware (tests/crtp_firmware.py)."""
    from groundstation.bridges.crazyflie.link import CflibLink

    link = CflibLink(firmware.uri)
    lost: list[str] = []
    toc = link.open(lost.append, timeout_s=10.0)
    try:
        assert toc == dict(FAKE_TOC)
        plan = plan_variables(CrazyflieSection(), toc, link.uri)
        got: list[tuple[str, int, dict[str, float]]] = []
        lock = threading.Lock()

        def on_data(block: str, ts: int, values: Any) -> None:
            with lock:
                got.append((block, ts, dict(values)))

        link.start_logging([*plan.fast, *plan.slow], on_data)
        names = {b.name for b in (*plan.fast, *plan.slow)}
        wait_for(lambda: {b for b, _, _ in list(got)} == names, "data of every block", 10.0)
        with lock:
            by_block = {b: v for b, _, v in got}
        assert by_block["tel0"]["acc.z"] == pytest.approx(1.0)
        assert by_block["tel1"]["motor.m3"] == 40000, "fetched as uint16"
        assert by_block["slow0"]["supervisor.info"] == 0b1011
        link.send_position_setpoint(0.1, 0.2, 0.5, 0.0)
        link.stop_motors()
        wait_for(lambda: any(d == b"\x03" for _, d in firmware.packets(0x09)), "emergency stop")
        assert lost == []
    finally:
        link.close()


def test_the_bridge_runs_on_cflib_over_udp(firmware: Any) -> None:
    from groundstation.bridges.crazyflie.link import CflibLink

    bus = InMemoryBus()
    telemetry: list[dict[str, Any]] = []
    bus.subscribe("tether/cf1/telemetry", lambda s: telemetry.append(_j(s)))
    bridge = CrazyflieBridge(CrazyflieSection(), bus, "cf1", CflibLink(firmware.uri))
    stop = threading.Event()
    rc: list[int] = []
    thread = threading.Thread(target=lambda: rc.append(bridge.run(stop)))
    thread.start()
    try:
        wait_for(lambda: len(telemetry) >= 20, "20 telemetry over cflib", 15.0)
    finally:
        stop.set()
        thread.join(10.0)
        bus.close()
    assert rc == [0]
    seqs = [t["seq"] for t in telemetry]
    assert seqs == list(range(len(seqs)))
    last = telemetry[-1]
    assert last["accel_mps2"] == pytest.approx([0.0, 0.0, G_MPS2])
    assert last["thrust_n"] == pytest.approx(thrust_n([40000.0] * 4, DEFAULT_MAP))
    assert last["armed"] is True and last["vbat_v"] == pytest.approx(3.9)
    stamps = [t["stamp_s"] for t in telemetry]
    assert all(b > a for a, b in itertools.pairwise(stamps))


# ------------------------------------------------------------------ gaps in the link


class _TimedLink(FakeLink):
    """The fake, recording when each position setpoint went out (host monotonic clock)."""

    def __init__(self, uri: str = "fake://hover") -> None:
        super().__init__(uri)
        self.setpoint_times: list[float] = []

    def send_position_setpoint(self, x_m: float, y_m: float, z_m: float, yaw_deg: float) -> None:
        self.setpoint_times.append(time.monotonic())
        super().send_position_setpoint(x_m, y_m, z_m, yaw_deg)


def test_runner_streams_setpoints_every_20_ms_at_a_half_hertz_log_rate(harness: Any) -> None:
    """At ``rate_hz = 0.5`` a log period lasts 2 s, four times the firmware's 0.5 s commander
    watchdog: setpoints must go out on their own cadence (every SETPOINT_PERIOD_S), holding
    the last one. Without a slow block the 2 s log period is the only data, which is no
    loss of the link either (``data_timeout_s`` 0.2 s is stretched to three log periods)."""
    from groundstation.bridges.crazyflie.runner import SETPOINT_PERIOD_S

    link = _TimedLink("fake://hover?missing=pm.vbat,supervisor.info")
    h = harness(link, rate_hz=0.5, data_timeout_s=0.2, silence_s=0.1)
    assert h.bridge.section.log_period_ms == 2000 and not h.bridge._plan.slow
    h.period(2)
    wait_for(lambda: len(h.telemetry) >= 2, "telemetry")
    stamp = h.telemetry[-1]["stamp_s"]
    h.publish("tether/cf1/cmd/setpoint", {"stamp_s": stamp, "position_m": [0.1, 0.0, 0.5]})
    # 1.2 s of setpoints with no new log data: longer than the 0.5 s watchdog (holding).
    times = link.setpoint_times
    wait_for(lambda: len(times) >= 2 and times[-1] - times[0] > 1.2, "1.2 s of setpoints")
    times = list(times)
    gaps = [b - a for a, b in itertools.pairwise(times)]
    assert sorted(gaps)[len(gaps) // 2] == pytest.approx(SETPOINT_PERIOD_S, abs=0.005)
    assert max(gaps) < 0.3, f"longest gap {max(gaps):.3f} s (the firmware levels after 0.5 s)"
    assert len(times) >= (times[-1] - times[0]) / 0.05, "at least 20 Hz on average"
    assert all(a[:3] == (0.1, 0.0, 0.5) for n, a in link.commands if n == "send_position_setpoint")
    # The service answers each Telemetry, every 2 s here: its silence is judged over three log
    # periods, so 1.2 s without a setpoint is no hold (nor a landing).
    assert h.bridge.gate.silence_s == pytest.approx(6.0)
    assert h.bridge.gate.phase(time.monotonic()) == "flying"
    assert link.opens == 1 and h.bridge.counts.get("link_lost", 0) == 0


def test_runner_warns_once_when_battery_or_armed_state_is_not_logged(
    harness: Any, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.WARNING, logger="groundstation.crazyflie")
    link = FakeLink("fake://hover?missing=pm.vbat,supervisor.info")
    h = harness(link)
    h.period(3)
    wait_for(lambda: len(h.telemetry) >= 3, "telemetry")
    assert "vbat_v" not in h.telemetry[-1]
    assert h.telemetry[-1].get("armed", True) is True, "the contract's default"
    warnings = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    (vbat,) = [m for m in warnings if "does not log pm.vbat" in m]
    (armed,) = [m for m in warnings if "does not log supervisor.info" in m]
    assert "no battery term" in vbat and "thrust_vbat_slope_per_v" in vbat
    assert "armed: true" in armed and "default" in armed
    wait_for(lambda: bool(h.status) and "not_logged" in h.status[-1], "status")
    not_logged = h.status[-1]["not_logged"]
    assert set(not_logged) == {"pm.vbat", "supervisor.info"}
    assert "no battery term" in not_logged["pm.vbat"]
    # A reconnection does not repeat the warnings.
    link.lose()
    wait_for(lambda: link.opens >= 2 and h.bridge.connected, "reconnected")
    again = [r.getMessage() for r in caplog.records if "does not log" in r.getMessage()]
    assert len(again) == 2
    # Choosing not to report the armed state is not a gap; a complete TOC has none.
    none = plan_variables(
        CrazyflieSection(armed_source="none"), {**FAKE_TOC, "supervisor.info": "x"}, "x"
    )
    assert none.not_logged == ()
    assert plan_variables(CrazyflieSection(), FAKE_TOC, "x").not_logged == ()


def test_runner_stops_with_the_reason_when_the_firmware_refuses_a_log_block(
    caplog: pytest.LogCaptureFixture,
) -> None:
    caplog.set_level(logging.ERROR, logger="groundstation.crazyflie")
    link = FakeLink("fake://hover?refuse=pm.vbat")
    bus = InMemoryBus()
    try:
        rc = CrazyflieBridge(CrazyflieSection(), bus, "cf1", link).run(threading.Event())
    finally:
        bus.close()
    assert rc == 2, "a refused block is not retried"
    msg = " ".join(r.getMessage() for r in caplog.records)
    assert "refused log block slow0" in msg and "pm.vbat" in msg
    assert "No more memory available" in msg
    assert _names(link) == ["open", "refused", "close"], "one attempt, no reconnection loop"


def test_cflib_link_raises_when_the_firmware_refuses_a_block() -> None:
    from groundstation.bridges.crazyflie.link import LinkError, LogBlockRefused

    toc = dict(FAKE_TOC)
    link, _, driver = _cflib_link(toc)
    driver.refuse = {list(toc).index("pm.vbat")}
    plan = plan_variables(CrazyflieSection(), toc, link.uri)
    with pytest.raises(LogBlockRefused) as info:
        link.start_logging([*plan.fast, *plan.slow], lambda b, t, v: None, timeout_s=5.0)
    assert info.value.block.name == "slow0"
    assert "No more memory available" in str(info.value) and "pm.vbat" in str(info.value)
    # No answer at all is a link problem, retried (not a refusal).
    silent, _, silent_driver = _cflib_link(toc)
    silent_driver.answers = False
    with pytest.raises(LinkError, match="did not start log block") as no_answer:
        silent.start_logging(list(plan.fast), lambda b, t, v: None, timeout_s=0.2)
    assert not isinstance(no_answer.value, LogBlockRefused)


def test_the_bridge_on_cflib_stops_when_the_firmware_refuses_a_block(
    caplog: pytest.LogCaptureFixture,
) -> None:
    """The refusal travels as the firmware sends it: an error code in the create-block
    answer, through cflib's UDP driver and its error callback."""
    from groundstation.bridges.crazyflie.link import CflibLink
    from tests.crtp_firmware import CrtpFirmware

    caplog.set_level(logging.ERROR, logger="groundstation.crazyflie")
    fw = CrtpFirmware(FAKE_TOC, refuse={"stateEstimate.qw"})
    bus = InMemoryBus()
    try:
        bridge = CrazyflieBridge(CrazyflieSection(), bus, "cf1", CflibLink(fw.uri))
        rc = bridge.run(threading.Event())
    finally:
        bus.close()
        fw.close()
    assert rc == 2
    msg = " ".join(r.getMessage() for r in caplog.records)
    assert "refused log block tel1" in msg and "No more memory available" in msg


# ------------------------------------------------------------------ when things go wrong
#
# The fake link's firmware model (FakeLink.firmware) flies what the bridge sends: it follows
# position setpoints at 1 m/s per axis, levels 0.5 s and cuts the motors (Locked) 2 s after the
# last setpoint, locks on an emergency stop, falls when the motors are off in the air (each
# arrival on the floor is an impact). The log data plays in real time on the fake's own thread,
# as cflib's would. These tests assert what happens to the drone.

BASE_M = (0.0, 0.0, 0.754)
LENGTH_M = 1.6


class GroundStation:
    """The service's side, reduced: an Estimate (the heartbeat) for each Telemetry and, while
    ``target`` is set, a Setpoint stamped with that Telemetry's stamp."""

    def __init__(self, h: Harness, target: tuple[float, float, float] | None) -> None:
        self.h = h
        self.alive = True
        self.target: Callable[[float], tuple[float, float, float]] | tuple[float, ...] | None
        self.target = target
        h.bus.subscribe("tether/cf1/telemetry", self._on_telemetry)

    def _on_telemetry(self, sample: Sample) -> None:
        if not self.alive:
            return
        tel = _j(sample)
        self.h.bus.publish(
            "tether/cf1/estimate",
            json.dumps({"seq": tel["seq"], "stamp_s": tel["stamp_s"]}).encode(),
        )
        target = self.target
        if callable(target):
            target = target(tel["stamp_s"])
        if target is not None:
            self.h.publish(
                "tether/cf1/cmd/setpoint", {"stamp_s": tel["stamp_s"], "position_m": list(target)}
            )


def _phases(h: Harness) -> list[str]:
    """The bridge's phases as reported on ``tether/cf1/bridge``, repeats removed."""
    out: list[str] = []
    for status in list(h.status):
        if not out or out[-1] != status["phase"]:
            out.append(status["phase"])
    return out


def _fly_to(h: Harness, link: FakeLink, z_m: float = 0.5) -> GroundStation:
    gs = GroundStation(h, (0.0, 0.0, z_m))
    wait_for(lambda: link.firmware.position_m[2] > z_m - 0.01, f"climbed to {z_m} m", 10.0)
    return gs


def _landed(link: FakeLink) -> bool:
    fw = link.firmware
    fw.advance()
    return fw.on_floor and not fw.motors_on


def test_a_lost_ground_station_holds_then_lands_the_drone_rather_than_dropping_it(
    harness: Any, caplog: pytest.LogCaptureFixture
) -> None:
    """The service dies mid-hover: the bridge reports the hold, then lands at the configured
    rate and switches the motors off on the floor: no fall, no lock, no link closed."""
    caplog.set_level(logging.INFO, logger="groundstation.crazyflie")
    link = FakeLink("fake://floor", realtime=True)
    h = harness(link, silence_s=0.1, hold_s=0.3, land_speed_mps=0.5)
    gs = _fly_to(h, link)
    wait_for(lambda: _phases(h)[-1:] == ["flying"], "flying")
    gs.alive = False  # the ground station is gone: no Estimate, no Setpoint
    t_kill = time.monotonic()
    wait_for(lambda: _landed(link), "landed with the motors off", 10.0)
    wait_for(lambda: h.status[-1]["phase"] == "idle", "idle reported")
    # The bridge reports the phase as it changes, then the motors off in a second status:
    # under load a test can read between the two.
    wait_for(lambda: h.status[-1]["motors_off"], "motors off reported")
    fw = link.firmware
    assert fw.impacts_mps == [], "landed, not dropped"
    assert not fw.locked and not h.bridge.gate.latched, "a landing locks nothing"
    phases = _phases(h)
    assert phases[phases.index("flying") :] == ["flying", "holding", "landing", "idle"]
    assert h.status[-1]["motors_off"] and "silent" in h.status[-1]["landing_reason"]
    # The descent, from the firmware's own track: 0.4 m -> 0.1 m at the landing rate.
    # list(): one C-level copy under the GIL (the fake firmware's thread still appends;
    # iterating the deque itself raised "deque mutated during iteration" in CI).
    track = [(t, z) for t, _, _, z in list(fw.track) if t > t_kill]
    t_hi = next(t for t, z in track if z < 0.4)
    t_lo = next(t for t, z in track if z < 0.1)
    # Never faster than asked (a drop is what this guards against); on a loaded host the
    # fake firmware, stepped in real time, may follow the ramp late, so slower is allowed.
    assert 0.1 <= 0.3 / (t_lo - t_hi) <= 0.5 * 1.3
    names = _names(link)
    assert names[-1] == "send_stop_setpoint" and "close" not in names and "stop_motors" not in names
    messages = [r.getMessage() for r in caplog.records]
    for words in ("holding", "landing (ground station silent", "landed"):
        assert any(words in m for m in messages), words


class _StallingBus(InMemoryBus):
    """A bus whose next Telemetry publish blocks the publisher (the bridge's thread)."""

    def __init__(self) -> None:
        super().__init__()
        self.stall_s = 0.0
        self.stalled = threading.Event()

    def publish(self, key: str, payload: bytes) -> None:
        if key.endswith("/telemetry") and self.stall_s > 0:
            stall_s, self.stall_s = self.stall_s, 0.0
            threading.Event().wait(stall_s)  # the stall itself, not a synchronisation
            self.stalled.set()
        super().publish(key, payload)


def test_a_stalled_bridge_thread_with_data_arriving_is_no_link_loss(harness: Any) -> None:
    """The bridge's thread blocked 1.2 s (longer than data_timeout_s 1 s) while log data
    keeps arriving on the link's thread: no link loss, no close (whose zero setpoint would cut
    the motors), no landing; the firmware only levelled meanwhile."""
    bus = _StallingBus()
    link = FakeLink("fake://floor", realtime=True)
    h = harness(link, bus, data_timeout_s=1.0, silence_s=0.1, hold_s=0.3)
    _fly_to(h, link)
    bus.stall_s = 1.2
    wait_for(bus.stalled.is_set, "the stall", 10.0)
    n = len(h.telemetry)
    wait_for(lambda: len(h.telemetry) > n + 100, "telemetry after the stall", 10.0)
    fw = link.firmware
    assert h.bridge.counts.get("link_lost", 0) == 0 and "close" not in _names(link)
    assert fw.motors_on and not fw.locked and fw.impacts_mps == []
    assert "landing" not in _phases(h) and h.bridge.gate.phase(time.monotonic()) == "flying"
    assert fw.position_m[2] == pytest.approx(0.5, abs=0.01)


def test_a_silent_link_while_flying_is_not_closed_but_landed(harness: Any) -> None:
    """No log data at all while flying: the link stays open and the bridge lands the drone on
    setpoints; only with the motors off is the link given up and opened again."""
    link = FakeLink("fake://floor", realtime=True)
    h = harness(link, data_timeout_s=0.3, silence_s=5.0, land_speed_mps=1.0)
    _fly_to(h, link, 0.3)
    link._stop_player.set()  # the radio hears nothing more; setpoints still get through
    wait_for(lambda: h.bridge.counts.get("link_silent", 0) == 1, "link reported silent")
    names = _names(link)
    assert "close" not in names
    wait_for(lambda: "close" in _names(link), "link given up once landed", 10.0)
    names = _names(link)
    assert names.index("send_stop_setpoint") < names.index("close")
    assert link.firmware.impacts_mps == [] and not link.firmware.locked
    assert any(s["link_silent"] for s in h.status)


def test_setpoints_beyond_the_tether_or_too_fast_are_refused_and_the_drone_stays_in_reach(
    harness: Any,
) -> None:
    """The ground station walks the target out of the tether's reach at 0.8 m/s in a random
    direction (seeded): the drone stops at the reach; a setpoint 50 m away and a 0.3 m jump
    are refused; each refusal is counted and reported."""
    rng = np.random.default_rng(21)
    azimuth = rng.uniform(0.0, 2.0 * math.pi)
    direction = (math.cos(azimuth), math.sin(azimuth))
    link = FakeLink("fake://floor", realtime=True)
    h = harness(link)
    gs = _fly_to(h, link)
    t0: list[float] = []

    def walk(stamp_s: float) -> tuple[float, float, float]:
        t0.append(stamp_s)
        d = 0.8 * (stamp_s - t0[0])
        return (d * direction[0], d * direction[1], 0.5)

    gs.target = walk
    wait_for(lambda: bool(t0) and t0[-1] - t0[0] > 2.5, "2.5 s of walking out", 10.0)
    wait_for(lambda: h.bridge.counts.get("setpoint_out_of_reach", 0) > 50, "refusals")
    held = h.bridge.gate.position_in_force(time.monotonic())
    assert held is not None
    limit_m = LENGTH_M - 0.05
    assert math.dist(BASE_M, held) == pytest.approx(limit_m, abs=0.02), "stopped at the reach"
    gs.target = (50.0, 0.0, 10.0)
    n = h.bridge.counts["setpoint_out_of_reach"]
    wait_for(lambda: h.bridge.counts["setpoint_out_of_reach"] > n + 5, "far setpoint refused")
    inward = (held[0] - 0.3 * direction[0], held[1] - 0.3 * direction[1], held[2])
    gs.target = inward
    wait_for(lambda: h.bridge.counts.get("setpoint_too_fast", 0) > 5, "jump refused")
    wait_for(lambda: h.status[-1]["dropped_setpoints"].get("too_fast", 0) > 0, "refusal reported")
    fw = link.firmware
    fw.advance()
    farthest = max(math.dist(BASE_M, p[1:]) for p in list(fw.track))
    assert farthest <= limit_m + 1e-6, f"the drone went {farthest:.3f} m from the base"
    sent = [a[:3] for n_, a in link.commands if n_ == "send_position_setpoint"]
    assert all(math.dist(BASE_M, p) <= limit_m + 1e-9 for p in sent)
    steps = [math.dist(a, b) for a, b in itertools.pairwise(sent)]
    # The refused 0.3 m jump never reached the drone. (The walk's own steps are 0.8 m/s times
    # the ground station's period: a few cm, more when a loaded host delays it; the gate
    # judges each by its stamps, so those pass.)
    assert max(steps) < 0.28, "no setpoint jumped"


def test_a_landing_stop_lands_without_a_lock_and_the_drone_flies_again(harness: Any) -> None:
    """tug-to-land's Stop (``kind: land``): down at the landing rate, motors off on the floor,
    no latch and no supervisor lock: the next setpoints fly again."""
    link = FakeLink("fake://floor", realtime=True)
    h = harness(link, land_speed_mps=0.5)
    gs = _fly_to(h, link)
    gs.target = None  # the service stops following and sends its Stop
    stamp = h.telemetry[-1]["stamp_s"]
    h.publish("tether/cf1/cmd/stop", {"stamp_s": stamp, "reason": "tug-to-land", "kind": "land"})
    wait_for(lambda: _landed(link), "landed with the motors off", 10.0)
    fw = link.firmware
    assert fw.impacts_mps == [] and not fw.locked and not h.bridge.gate.latched
    assert "stop_motors" not in _names(link)
    wait_for(lambda: h.status[-1]["phase"] == "idle", "idle reported")
    assert "landing" in _phases(h) and "Stop (tug-to-land)" in h.status[-1]["landing_reason"]
    gs.target = (0.0, 0.0, 0.3)
    wait_for(lambda: fw.position_m[2] > 0.29, "flying again", 10.0)


def test_an_emergency_stop_cuts_the_motors_and_locks_until_a_power_cycle(harness: Any) -> None:
    """The operator's Stop (no ``kind``): motors off at once (the drone falls: that is what an
    emergency stop is), the bridge latches and the supervisor locks; re-arming lifts the
    bridge's latch, but the firmware flies again only after a power cycle."""
    link = FakeLink("fake://floor", realtime=True)
    h = harness(link)
    gs = _fly_to(h, link, 0.3)
    stamp = h.telemetry[-1]["stamp_s"]
    h.publish("tether/cf1/cmd/stop", {"stamp_s": stamp, "reason": "operator"})
    wait_for(lambda: _landed(link), "motors off, on the floor", 10.0)
    fw = link.firmware
    assert fw.locked and len(fw.impacts_mps) == 1 and h.bridge.gate.latched
    wait_for(lambda: h.bridge.counts.get("setpoint_latched", 0) > 5, "setpoints refused")
    h.publish("tether/cf1/cmd/rearm", {})
    wait_for(
        lambda: h.bridge.counts.get("setpoints_sent", 0) > 0 and not h.bridge.gate.latched,
        "re-armed",
    )
    n = h.bridge.counts["setpoints_sent"]
    wait_for(lambda: h.bridge.counts["setpoints_sent"] > n + 10, "setpoints sent again")
    assert fw.on_floor and fw.locked, "Locked: the setpoints do nothing"
    fw.power_cycle()
    wait_for(lambda: fw.position_m[2] > 0.29, "flying after a power cycle", 10.0)
    assert gs.alive


# ------------------------------------------------------------------ more that goes wrong


def _counted(h: Harness, kind: str, n: int = 1) -> Callable[[], bool]:
    return lambda: h.bridge.counts.get(kind, 0) >= n


def _params(link: FakeLink) -> list[tuple[Any, ...]]:
    return [a for n, a in link.commands if n == "set_param"]


def test_onboard_position_and_its_variances_take_a_block_of_their_own() -> None:
    """stateEstimate.x/y/z and kalman.varX/Y/Z (24 bytes) cannot join the two full fast
    packets: a third; the velocity variances the settle check reads join the slow block."""
    from groundstation.bridges.crazyflie.bridge import POSITION, POSITION_VAR, VELOCITY_VAR

    plan = plan_variables(CrazyflieSection(onboard_position="lighthouse"), FAKE_TOC, "x")
    assert plan.position and plan.settle
    assert len(plan.fast) == 3
    assert plan.fast[2].variables == (*POSITION, *POSITION_VAR)
    assert [v for b in plan.slow for v in b.variables] == [
        "pm.vbat",
        "supervisor.info",
        *VELOCITY_VAR,
    ]
    for block in (*plan.fast, *plan.slow):
        assert _block_bytes(block) <= MAX_BLOCK_BYTES
    # motion capture into the drone needs the settle check, not the onboard position
    extpos = plan_variables(CrazyflieSection(send_extpos=True), FAKE_TOC, "x")
    assert len(extpos.fast) == 2 and extpos.settle and not extpos.position
    no_kalman = {k: v for k, v in FAKE_TOC.items() if not k.startswith("kalman.")}
    with pytest.raises(MissingVariables, match=r"kalman\.varX.*Kalman estimator"):
        plan_variables(CrazyflieSection(onboard_position="loco"), no_kalman, "x")


def test_telemetry_position_from_mocap_first_else_the_onboard_estimator_with_its_sigma() -> None:
    section = CrazyflieSection(onboard_position="loco", mocap_stale_s=0.1)
    plan = plan_variables(section, FAKE_TOC, "x")
    values = {
        **_values(),
        "stateEstimate.x": 0.4,
        "stateEstimate.y": -0.1,
        "stateEstimate.z": 0.6,
        "kalman.varX": 0.0016,
        "kalman.varY": 0.0009,
        "kalman.varZ": 1e-6,  # the firmware's floor
    }
    tel = build_telemetry(Aligned(0, values), plan, section, 0, {}, None, 0.0)
    assert tel.position_m == pytest.approx((0.4, -0.1, 0.6))
    assert tel.position_source == "loco"
    assert tel.position_std_m == pytest.approx((0.04, 0.03, 0.001))
    pose = MocapPose((0.3, -0.2, 0.5), None, received_s=10.0)
    tel = build_telemetry(Aligned(0, values), plan, section, 0, {}, pose, 10.05)
    assert tel.position_m == (0.3, -0.2, 0.5) and tel.position_source == "mocap"
    assert tel.position_std_m is None
    broken = {**values, "kalman.varY": math.nan}
    tel = build_telemetry(Aligned(0, broken), plan, section, 0, {}, None, 0.0)
    assert tel.position_m is None, "no σ, no position"


def test_settle_watch_is_cflibs_reset_estimator() -> None:
    """After a reset each velocity variance must stay within the spread over the window; one
    growing (no position measured) never settles; a new reset starts again."""
    from groundstation.bridges.crazyflie.bridge import SettleWatch

    watch = SettleWatch(window_s=4.5, spread=0.001)
    for i in range(100):
        watch.push(i * 0.1, (2e-4, 2e-4, 2e-4))
    assert not watch.settled(10.0), "no reset yet: nothing counts"
    watch.reset(10.0)
    t = 10.0
    while t < 14.4:  # settling: v = 2e-4 + 0.01·exp(-t/0.5)
        watch.push(t, (2e-4 + 0.01 * math.exp(-(t - 10.0) / 0.5),) * 3)
        assert not watch.settled(t)
        t += 0.1
    while not watch.settled(t):
        assert t < 20.0, "settles once the transient is inside the spread for 4.5 s"
        watch.push(t, (2e-4 + 0.01 * math.exp(-(t - 10.0) / 0.5),) * 3)
        t += 0.1
    # 0.01·e^{-(t-4.5)/0.5}·(1 - e^{-9}) < 0.001: some 5.6 s after the reset
    assert 5.3 < t - 10.0 < 6.0
    assert not watch.settled(t + 2.0), "a stale variance is no settled estimator"
    watch.reset(t)
    for i in range(200):  # growing at 0.05 per second: never settles
        watch.push(t + 0.1 * i, (0.01 + 0.005 * i, 2e-4, 2e-4))
        assert not watch.settled(t + 0.1 * i)


def test_lighthouse_position_is_published_with_its_sigma_and_take_off_flies_from_it(
    harness: Any,
) -> None:
    """A Lighthouse deck, no motion capture: the estimator is reset on the floor, take-off is
    refused until its variances settle, then the drone climbs straight up from the onboard
    position, and the published position follows the firmware's within its noise."""
    link = FakeLink("fake://floor?positioning=lighthouse", realtime=True, start_m=(0.3, -0.2, 0))
    h = harness(link, onboard_position="lighthouse", estimator_settle_s=0.5)
    fw = link.firmware
    wait_for(_counted(h, "estimator_resets"), "the estimator reset on the floor")
    assert _params(link)[0] == ("kalman.resetEstimation", 1.0)
    h.publish("tether/cf1/cmd/takeoff", {"height_m": 0.4, "speed_mps": 0.5})
    wait_for(_counted(h, "takeoff_refused"), "take-off refused before the estimator settles")
    assert not fw.motors_on and fw.position_m[2] == 0.0
    assert h.status[-1]["estimator"]["settled"] is False
    wait_for(_counted(h, "estimator_settled"), "the estimator settled", 10.0)
    wait_for(lambda: ("kalman.resetEstimation", 0.0) in _params(link), "reset flag cleared")
    tel = h.telemetry[-1]
    assert tel["position_source"] == "lighthouse"
    assert max(tel["position_std_m"]) < 0.005
    assert tel["position_m"] == pytest.approx([0.3, -0.2, 0.0], abs=0.01)
    h.publish("tether/cf1/cmd/takeoff", {"height_m": 0.4, "speed_mps": 0.5})
    wait_for(lambda: fw.position_m[2] > 0.399, "climbed to 0.4 m", 10.0)
    assert fw.position_m[:2] == pytest.approx([0.3, -0.2], abs=0.01), "up from where it sat"
    assert h.bridge.counts["takeoff_refused"] == 1
    wait_for(
        lambda: abs(h.telemetry[-1]["position_m"][2] - fw.position_m[2]) < 0.01,
        "the published position at the firmware's height",
    )
    assert h.close() == 0


def test_flow_deck_odometry_starts_where_configured_and_its_xy_sigma_says_untrusted(
    harness: Any,
) -> None:
    """A Flow deck measures height and velocity: the bridge writes kalman.initialX/Y/Z before
    the reset so that the odometry starts in the world frame, take-off flies from there, and
    the published σ says x/y are not to be trusted (the service then does not, below)."""
    link = FakeLink("fake://floor?positioning=flow", realtime=True, start_m=(0.3, -0.2, 0))
    h = harness(
        link,
        onboard_position="flow",
        estimator_settle_s=0.5,
        estimator_initial_m=(0.3, -0.2, 0.0),
    )
    wait_for(_counted(h, "estimator_settled"), "the estimator settled", 10.0)
    assert _params(link)[:4] == [
        ("kalman.initialX", 0.3),
        ("kalman.initialY", -0.2),
        ("kalman.initialZ", 0.0),
        ("kalman.resetEstimation", 1.0),
    ]
    tel = h.telemetry[-1]
    assert tel["position_source"] == "flow"
    assert tel["position_m"][:2] == pytest.approx([0.3, -0.2], abs=0.05)
    assert min(tel["position_std_m"][:2]) > 5.0 and tel["position_std_m"][2] < 0.02
    h.publish("tether/cf1/cmd/takeoff", {"height_m": 0.3, "speed_mps": 0.5})
    wait_for(lambda: link.firmware.position_m[2] > 0.299, "climbed", 10.0)
    assert link.firmware.position_m[:2] == pytest.approx([0.3, -0.2], abs=0.05)


def test_the_service_uses_an_onboard_position_only_within_its_sigma_limit() -> None:
    """The pipeline: a Lighthouse position (σ 2 mm) is used as motion capture is (follow may
    be switched on without a calibration); a Flow deck's (σ_xy 10 m) is no position: one
    warning Event, and follow stays off as without one."""
    from groundstation.bus import Sample
    from groundstation.pipeline import Pipeline

    def run(std: list[float], source: str) -> tuple[Any, list[Any]]:
        events: list[Any] = []
        pipe = Pipeline(load_settings(None, use_env=False), on_event=lambda d, e: events.append(e))
        for seq in range(3):
            tel = {
                "seq": seq,
                "stamp_s": 0.01 * seq,
                "accel_mps2": [0, 0, 9.81],
                "quat_wxyz": [1, 0, 0, 0],
                "thrust_n": 0.3,
                "position_m": [0.3, -0.2, 0.5],
                "position_source": source,
                "position_std_m": std,
            }
            pipe.handle(Sample("tether/cf1/telemetry", json.dumps(tel).encode()), 0.01 * seq)
        pipe.handle(Sample("tether/cf1/follow", b'{"enabled": true}'), 0.03)
        return pipe.drones["cf1"], events

    trusted, events = run([0.002, 0.002, 0.002], "lighthouse")
    assert trusted.mocap_m == (0.3, -0.2, 0.5)
    assert trusted.follow_state.enabled
    assert not [e for e in events if e.field == "position_std_m"]
    untrusted, events = run([10.0, 10.0, 0.005], "flow")
    assert untrusted.mocap_m is None
    assert not untrusted.follow_state.enabled
    warned = [e for e in events if e.field == "position_std_m"]
    assert len(warned) == 1 and "flow" in warned[0].reason and "0.05" in warned[0].reason


class _MocapStream:
    """A motion-capture system publishing the fake drone's true pose at ``rate_hz`` until
    stopped (its pacing is the stream's own rate, not a synchronisation)."""

    def __init__(self, h: Harness, link: FakeLink, rate_hz: float = 200.0) -> None:
        self.h, self.link, self.period_s = h, link, 1.0 / rate_hz
        self.stop = threading.Event()
        self.sent = 0
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self) -> None:
        while not self.stop.wait(self.period_s):
            fw = self.link.firmware
            fw.advance()
            pose = {"position_m": [float(v) for v in fw.position_m], "quat_wxyz": [1, 0, 0, 0]}
            self.h.publish("mocap/cf1", pose)
            self.sent += 1

    def close(self) -> None:
        self.stop.set()
        self.thread.join(2.0)


def test_mocap_into_the_drone_reset_settle_then_take_off_as_bitcraze_does_it(
    harness: Any,
) -> None:
    """send_extpos: on the floor the bridge selects the Kalman estimator, sets
    locSrv.extQuatStdDev, resets it (1, then 0 0.1 s later); with no pose streaming the
    variances grow and take-off is refused; once poses stream they settle and the drone takes
    off. Poses go out at most extpos_rate_hz, the latest winning."""
    link = FakeLink("fake://floor", realtime=True, start_m=(0.2, 0.1, 0.0))
    h = harness(
        link,
        mocap_key="mocap/{drone}",
        send_extpos=True,
        estimator_settle_s=0.5,
        extpos_rate_hz=50.0,
        mocap_stale_s=0.2,
    )
    fw = link.firmware
    wait_for(_counted(h, "estimator_resets"), "the estimator reset on the floor")
    assert _params(link)[:3] == [
        ("stabilizer.estimator", 2.0),
        ("locSrv.extQuatStdDev", 8.0e-3),
        ("kalman.resetEstimation", 1.0),
    ]
    # No motion capture: the variances grow (0.05 per s); a second of it, then take-off.
    wait_for(lambda: fw.kalman_var_vel[0] > 0.06, "a second without poses", 10.0)
    h.publish("tether/cf1/cmd/takeoff", {"height_m": 0.4, "speed_mps": 0.5})
    wait_for(_counted(h, "takeoff_refused"), "take-off refused: the estimator has not settled")
    assert not fw.motors_on and fw.position_m[2] == 0.0
    assert "estimator_settled" not in h.bridge.counts
    stream = _MocapStream(h, link)
    try:
        wait_for(_counted(h, "estimator_settled"), "settled once poses stream", 10.0)
        h.publish("tether/cf1/cmd/takeoff", {"height_m": 0.4, "speed_mps": 0.5})
        wait_for(lambda: fw.position_m[2] > 0.399, "climbed to 0.4 m", 10.0)
        assert fw.position_m[:2] == pytest.approx([0.2, 0.1], abs=1e-6)
        # the estimator tracks the poses it is sent (within 1 cm once hovering)
        wait_for(
            lambda: float(np.max(np.abs(fw.kalman_position_m - fw.position_m))) < 0.01,
            "the onboard estimate on the poses",
        )
    finally:
        stream.close()
    times = link.extpos_times
    gaps = np.diff(times)
    # The limit holds on the bridge's clock; the fake stamps a pose when the call reaches
    # it, which a loaded host can delay for one pose and not the next: judge the mean rate,
    # and no two poses closer than half a period.
    assert len(times) > 20 and gaps.min() >= 0.5 / 50.0, f"shortest gap {gaps.min():.4f} s"
    assert (len(times) - 1) / (times[-1] - times[0]) <= 50.0 * 1.05
    assert h.bridge.counts["extpos_superseded"] > 0, "faster poses were superseded, not queued"
    assert stream.sent > 2 * len(times)
    # the latest pose wins: a last, distinct pose reaches the drone
    h.publish("mocap/cf1", {"position_m": [0.2, 0.1, 0.4321]})
    wait_for(
        lambda: any(n == "send_extpos" and a[2] == 0.4321 for n, a in list(link.commands)),
        "the last pose sent",
    )


def test_without_mocap_the_reset_waits_for_the_floor_and_a_hovering_drone_is_not_reset(
    harness: Any,
) -> None:
    """Connected to a drone already flying: no reset (a reset in flight throws the estimate
    to kalman.initial*), and take-off is refused with the reason."""
    link = FakeLink("fake://hover", realtime=True)
    h = harness(link, send_extpos=True, mocap_key="mocap/{drone}", estimator_settle_s=0.5)
    wait_for(lambda: len(h.telemetry) >= 50, "half a second of telemetry")
    assert _params(link) == [] and "estimator_resets" not in h.bridge.counts
    h.publish("tether/cf1/cmd/takeoff", {"height_m": 0.6})
    wait_for(_counted(h, "takeoff_refused"), "take-off refused")
    assert h.status[-1]["estimator"] == {
        "required": True,
        "reset": False,
        "settled": False,
        "spread": None,
        "error": "",
        "onboard_position_m": None,
    }


def test_one_process_runs_several_links_each_its_own_drone() -> None:
    """run_bridges: three fakes on one bus. Commands reach only their drone; a link whose
    firmware lacks a variable ends (exit 2) without stopping the others."""
    from groundstation.bridges.crazyflie.runner import run_bridges

    bus = InMemoryBus()
    links = {
        "cf1": FakeLink("fake://hover", realtime=True),
        "cf2": FakeLink("fake://hover", realtime=True, start_m=(0.5, 0.0, 0.5)),
        "cf3": FakeLink("fake://hover?missing=acc.x", realtime=True),
    }
    telemetry: dict[str, list[dict[str, Any]]] = {d: [] for d in links}
    for drone in links:
        bus.subscribe(f"tether/{drone}/telemetry", lambda s, d=drone: telemetry[d].append(_j(s)))
    section = CrazyflieSection(data_timeout_s=60.0, silence_s=60.0)
    reach = ((0.0, 0.0, 0.754), 1.6)
    bridges = [
        CrazyflieBridge(section, bus, drone, link, reach=reach) for drone, link in links.items()
    ]
    stop = threading.Event()
    rc: list[int] = []
    thread = threading.Thread(target=lambda: rc.append(run_bridges(bridges, stop)))
    thread.start()
    try:
        wait_for(lambda: _names(links["cf3"]) == ["open", "close"], "cf3 refused")
        wait_for(lambda: min(len(telemetry["cf1"]), len(telemetry["cf2"])) >= 20, "both stream")
        stamp = telemetry["cf2"][-1]["stamp_s"]
        bus.publish(
            "tether/cf2/cmd/setpoint",
            json.dumps({"stamp_s": stamp, "position_m": [0.5, 0.0, 0.7]}).encode(),
        )
        fw1, fw2 = links["cf1"].firmware, links["cf2"].firmware
        wait_for(lambda: fw2.position_m[2] > 0.699, "cf2 climbed", 10.0)
        assert fw1.position_m[2] == pytest.approx(0.5) and fw1.target_m is None
        bus.publish("tether/cf1/cmd/stop", b'{"stamp_s": 0.0, "reason": "test"}')
        wait_for(lambda: fw1.locked, "cf1 stopped")
        assert fw2.motors_on and not fw2.locked, "cf2 flies on"
        n = len(telemetry["cf2"])
        wait_for(lambda: len(telemetry["cf2"]) > n + 20, "cf2 still streaming")
        assert telemetry["cf3"] == []
    finally:
        stop.set()
        thread.join(10.0)
        bus.close()
    assert rc == [2], "the worst exit code: cf3's missing variable"


def test_serial_is_refused_with_the_reason_and_scan_connects_to_nothing() -> None:
    from groundstation.bridges.crazyflie import _radio_address, scan
    from groundstation.bridges.crazyflie.link import CflibLink, LinkError

    with pytest.raises(LinkError, match=r"serial:// is not supported.*pyserial.*radio://"):
        CflibLink("serial://ttyUSB0")
    with pytest.raises(LinkError, match="serial://"):
        scan(["serial://ttyUSB0"])
    assert scan(["fake://hover", "fake://floor?absent=1"]) == ["fake://hover"]
    assert _radio_address("radio://0/80/2M/E7E7E7E701") == 0xE7E7E7E701
    assert _radio_address("radio://0/80/2M") is None
    with pytest.raises(LinkError, match="hexadecimal"):
        _radio_address("radio://0/80/2M/XYZ")
