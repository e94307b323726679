"""Each stage of groundstation.estimator alone: the gate, the observation, the checks, the
contact, the filter's control, the localization's inputs, follow's control, the Estimate's fields.

The Pipeline's own tests (test_pipeline*.py, test_perf_equivalence.py) run them together;
here each stage's rules are pinned where a reader of that stage looks for them.
"""

from __future__ import annotations

import json
import math
from typing import Any

import numpy as np
import pytest

from groundstation import contact as contact_mod
from groundstation import follow as follow_mod
from groundstation.attitude import Rows, rows_from_quat_wxyz
from groundstation.bias_kalman import BiasKalman
from groundstation.calibration import RestCalibrator
from groundstation.config import LocalizationSection
from groundstation.estimator import checks, output
from groundstation.estimator.contact_control import contact_decide
from groundstation.estimator.filter_control import FilterControl, liftoff_prior_std_n
from groundstation.estimator.follow_control import (
    UNTRUSTED_POSITION_REASON,
    FollowCommandState,
    apply_command,
    follow_decide,
    refuse_command,
)
from groundstation.estimator.gate import GateState, gate_step, mark_stale
from groundstation.estimator.localize_control import (
    LocalizeIn,
    fresh_angle,
    localize_one,
)
from groundstation.estimator.observation import learn_slow, observe
from groundstation.localization import AngleObservation
from groundstation.messages import Estimate, FollowCommand, FollowInfo, Telemetry
from groundstation.slow_accel import SlowAccelParams, SlowAccelState
from groundstation.tension import TensionError, TensionFilterParams, observe_tension

MASS_KG = 0.030
G = 9.81


def _telemetry(**kw: object) -> Telemetry:
    fields: dict[str, object] = {
        "seq": 0,
        "stamp_s": 0.0,
        "accel_mps2": (0.0, 0.0, G),
        "quat_wxyz": (1.0, 0.0, 0.0, 0.0),
        "thrust_n": MASS_KG * G,
    }
    fields.update(kw)
    return Telemetry.model_validate(fields)


# ---------------------------------------------------------------- gate

GAP_S = 0.5  # [service] stale_after_s's default


def test_gate_accepts_in_order_and_counts_forward_gaps() -> None:
    state, v = gate_step(GateState(), seq=0, stamp_s=1.0, now_s=10.0, max_gap_s=GAP_S)
    assert v.drop_kind is None and v.resumed and v.dt_s == 0.0  # a new stream resumes
    state, v = gate_step(state, seq=1, stamp_s=1.004, now_s=10.004, max_gap_s=GAP_S)
    assert v.drop_kind is None and not v.resumed and v.dt_s == pytest.approx(0.004)
    state, v = gate_step(state, seq=5, stamp_s=1.02, now_s=10.02, max_gap_s=GAP_S)
    assert v.seq_gap == 3 and v.dt_s == pytest.approx(0.016)
    assert (state.last_seq, state.last_stamp_s, state.last_seen_s) == (5, 1.02, 10.02)


@pytest.mark.parametrize(
    ("seq", "stamp_s", "kind"),
    [(3, 2.0, "seq_repeated"), (2, 2.0, "seq_backwards"), (4, 1.0, "stamp_backwards")],
)
def test_gate_refuses_repeats_and_backwards_and_keeps_its_state(
    seq: int, stamp_s: float, kind: str
) -> None:
    state = GateState(last_seq=3, last_stamp_s=1.5, last_seen_s=10.0, stale=False)
    after, v = gate_step(state, seq=seq, stamp_s=stamp_s, now_s=10.01, max_gap_s=GAP_S, drone="cf1")
    assert v.drop_kind == kind and "cf1" in v.detail
    assert after is state


def test_gate_resumes_after_silence_or_staleness_in_any_order() -> None:
    state = GateState(last_seq=100, last_stamp_s=50.0, last_seen_s=10.0, stale=False)
    # A rebooted drone counts from 0 again, after more than the stale time of silence.
    after, v = gate_step(state, seq=0, stamp_s=0.1, now_s=10.0 + GAP_S + 0.01, max_gap_s=GAP_S)
    assert v.drop_kind is None and v.resumed and v.dt_s == 0.0 and v.seq_gap == 0
    assert after.last_seq == 0 and not after.stale
    # Within the gap the same message is refused ...
    _, v = gate_step(state, seq=0, stamp_s=0.1, now_s=10.0 + GAP_S, max_gap_s=GAP_S)
    assert v.drop_kind == "seq_backwards"
    # ... unless the drone was marked stale.
    _, v = gate_step(mark_stale(state), seq=0, stamp_s=0.1, now_s=10.1, max_gap_s=GAP_S)
    assert v.drop_kind is None and v.resumed


# ---------------------------------------------------------------- observation


def test_observation_is_observe_tension_of_the_reading_less_the_rest_offset() -> None:
    msg = _telemetry(accel_mps2=(0.3, -0.2, G + 0.5), thrust_n=0.35)
    got = observe(
        msg,
        mass_kg=MASS_KG,
        calibration=None,
        rest_offset_xy_mps2=(0.1, -0.05),
        slow=None,
        ground_thrust_ratio=0.5,
    )
    want = observe_tension((0.2, -0.15, G + 0.5), msg.quat_wxyz, 0.35, MASS_KG, armed=True)
    assert got.accel_read_body_mps2 == (0.3 - 0.1, -0.2 + 0.05, G + 0.5)
    assert got.observation.tension_world_n is not None and want.tension_world_n is not None
    np.testing.assert_allclose(got.observation.tension_world_n, want.tension_world_n)


def test_observation_with_the_slow_stage_subtracts_beta_but_reports_the_raw_reading() -> None:
    msg = _telemetry(accel_mps2=(0.3, 0.0, G))
    slow = SlowAccelState(kf=BiasKalman(bias_body_mps2=(0.3, 0.0, 0.0)))
    got = observe(
        msg,
        mass_kg=MASS_KG,
        calibration=None,
        rest_offset_xy_mps2=None,
        slow=slow,
        ground_thrust_ratio=0.5,
    )
    assert got.accel_read_body_mps2 == (0.3, 0.0, G)  # what the slow stage learns from
    assert got.observation.tension_world_n is not None
    # β removed: hover thrust against g, no sideways pull left.
    np.testing.assert_allclose(got.observation.tension_world_n, (0.0, 0.0, 0.0), atol=1e-12)


def test_observation_refuses_a_degenerate_quaternion() -> None:
    with pytest.raises(TensionError):
        observe(
            _telemetry(quat_wxyz=(0.0, 0.0, 0.0, 0.0)),
            mass_kg=MASS_KG,
            calibration=None,
            rest_offset_xy_mps2=None,
            slow=None,
            ground_thrust_ratio=0.5,
        )


def _learn(state: SlowAccelState, rest: RestCalibrator, msg: Telemetry) -> SlowAccelState:
    """One message through the rest detector, then the slow stage (as the drone does)."""
    rest.update(msg.stamp_s, msg.accel_mps2, msg.quat_wxyz, msg.armed, msg.gyro_rps)
    obs = observe(
        msg,
        mass_kg=MASS_KG,
        calibration=None,
        rest_offset_xy_mps2=None,
        slow=state,
        ground_thrust_ratio=0.5,
    )
    return learn_slow(
        state,
        SlowAccelParams(),
        msg,
        obs,
        dt_s=0.01,
        on_ground=True,
        calibration=None,
        still=rest.still,
        rest_mean_body_mps2=rest.rest_mean_body_mps2,
    )


def test_learn_slow_learns_at_rest_only_when_disarmed_and_still() -> None:
    """β at rest is the rest detector's window mean (the one test of stillness), once the
    window has lasted ``attitude.STILL_WINDOW_S``; a sample that is not still holds β."""
    state = SlowAccelState()
    rest = RestCalibrator()
    still = _telemetry(armed=False, thrust_n=0.0, accel_mps2=(0.2, 0.0, G), gyro_rps=(0, 0, 0))
    for k in range(90):  # 0.9 s: not yet a rest
        state = _learn(state, rest, still.model_copy(update={"seq": k, "stamp_s": 0.01 * k}))
    assert not state.learnt_at_rest and state.bias_body_mps2 == (0.0, 0.0, 0.0)
    for k in range(90, 120):
        state = _learn(state, rest, still.model_copy(update={"seq": k, "stamp_s": 0.01 * k}))
    assert state.learnt_at_rest and state.bias_body_mps2[0] == pytest.approx(0.2, abs=1e-9)
    assert state.bias_body_mps2[2] == pytest.approx(0.0, abs=1e-9)  # z too, not only x/y
    # Turning (gyro) on the floor: no rest sample, the state is held.
    turning = still.model_copy(
        update={"seq": 199, "stamp_s": 1.2, "gyro_rps": (0.0, 0.0, 1.0), "accel_mps2": (1, 0, G)}
    )
    held = _learn(state, rest, turning)
    assert not rest.still and held.bias_body_mps2 == state.bias_body_mps2


# ---------------------------------------------------------------- checks


def test_battery_check_is_silent_on_the_ground_and_without_a_range() -> None:
    assert checks.battery_outside((3.5, 4.1), 3.3, on_ground=False) is True
    assert checks.battery_outside((3.5, 4.1), 3.8, on_ground=False) is False
    assert checks.battery_outside((3.5, 4.1), 3.3, on_ground=True) is None
    assert checks.battery_outside(None, 3.3, on_ground=False) is None
    assert checks.battery_outside((3.5, 4.1), None, on_ground=False) is None


def test_position_check_refuses_only_a_position_whose_sigma_is_too_large() -> None:
    base = {"position_m": (1.0, 0.0, 1.0)}
    assert checks.position_too_uncertain(_telemetry(**base, position_std_m=(10, 10, 0.1)), 0.5)
    assert not checks.position_too_uncertain(_telemetry(**base, position_std_m=(0.1,) * 3), 0.5)
    assert not checks.position_too_uncertain(_telemetry(**base), 0.5)  # motion capture's σ


def test_rest_missing_is_set_at_arming_without_offset_and_cleared_at_disarm() -> None:
    f = checks.rest_missing_at_arming
    assert f(was_armed=False, armed=True, offset_in_force=False, missing_before=False)
    assert not f(was_armed=False, armed=True, offset_in_force=True, missing_before=False)
    assert f(was_armed=True, armed=True, offset_in_force=True, missing_before=True)  # holds
    assert not f(was_armed=True, armed=False, offset_in_force=False, missing_before=True)


# ---------------------------------------------------------------- contact


def _rows(msg: Telemetry) -> Rows:
    """The attitude's rows, as the observation stage hands them on."""
    return rows_from_quat_wxyz(msg.quat_wxyz)


def test_contact_stage_hands_contact_step_this_messages_evidence() -> None:
    """The calibrated thrust, the IMU's world vertical acceleration and motion capture's
    height go to contact_step as they are; the state it returns is the stage's."""
    params = contact_mod.ContactParams()
    state = contact_mod.ContactState()
    msg = _telemetry(
        accel_mps2=(0.1, 0.0, G + 0.4), quat_wxyz=(0.99, 0.1, 0.0, 0.0), position_m=(0.2, 0.0, 0.7)
    )
    got = contact_decide(state, params, msg, thrust_n=0.31, mass_kg=MASS_KG, dt_s=0.004,
                         floor_z_m=0.0, rotation_rows_world_body=_rows(msg),
                         sample_sigmas=5.0, bias_step_std_mps2=0.05,
                         height_std_m=0.002)  # fmt: skip
    want = contact_mod.contact_step(
        state,
        params,
        dt_s=0.004,
        armed=True,
        thrust_n=0.31,
        mass_kg=MASS_KG,
        vertical_accel_mps2=contact_mod.vertical_accel_mps2(msg.accel_mps2, msg.quat_wxyz),
        height_m=0.7,
        floor_z_m=0.0,
        sample_sigmas=5.0,
        bias_step_std_mps2=0.05,
        height_std_m=0.002,
    )
    assert got.state == want and got.on_ground == want.on_ground


def test_contact_stage_judges_a_climb_against_the_vibration_it_is_given() -> None:
    """Without motion capture a climb is judged against the vertical vibration the stage is
    handed (the tension filter's measure, DroneEstimator.front): 2 m/s^2 up for 0.3 s on
    the floor at 0.9 of the weight is a climb against a quiet floor, none against a loud
    one, and none before any vibration is known."""
    params = contact_mod.ContactParams()
    ends = {}
    for label, var in (("quiet", 1e-4), ("loud", 100.0), ("unknown", None)):
        state = contact_mod.ContactState(rest_seen=True)
        for k in range(75):
            msg = _telemetry(seq=k, stamp_s=0.004 * k, accel_mps2=(0.0, 0.0, G + 2.0))
            state, _ = contact_decide(
                state,
                params,
                msg,
                thrust_n=0.9 * MASS_KG * G,
                mass_kg=MASS_KG,
                dt_s=0.004,
                floor_z_m=0.0,
                rotation_rows_world_body=_rows(msg),
                vertical_noise_var_mps4=var,
                sample_sigmas=5.55,
                bias_step_std_mps2=0.05,
                height_std_m=0.002,
            )
            if not state.on_ground:
                break
        ends[label] = (state.on_ground, state.reason)
    assert ends["quiet"] == (False, "climbing")
    assert ends["loud"][0] and ends["unknown"][0]


def test_contact_stage_a_disarmed_drone_is_on_the_ground_and_a_dip_is_not() -> None:
    params = contact_mod.ContactParams()
    state = contact_mod.ContactState()
    # Hovering at 1 m (motion capture): airborne within a few samples.
    for k in range(50):
        msg = _telemetry(seq=k, stamp_s=0.004 * k, position_m=(0.0, 0.0, 1.0))
        state, on_ground = contact_decide(
            state,
            params,
            msg,
            thrust_n=MASS_KG * G,
            mass_kg=MASS_KG,
            dt_s=0.004,
            floor_z_m=0.0,
            rotation_rows_world_body=_rows(msg),
            sample_sigmas=5.55,
            bias_step_std_mps2=0.05,
            height_std_m=0.002,
        )
    assert not on_ground
    # A thrust dip in the air (the specific force is thrust / m, far below g): still air.
    for k in range(50, 150):
        msg = _telemetry(seq=k, stamp_s=0.004 * k, accel_mps2=(0.0, 0.0, 0.7), thrust_n=0.02)
        state, on_ground = contact_decide(
            state,
            params,
            msg,
            thrust_n=0.02,
            mass_kg=MASS_KG,
            dt_s=0.004,
            floor_z_m=0.0,
            rotation_rows_world_body=_rows(msg),
            sample_sigmas=5.55,
            bias_step_std_mps2=0.05,
            height_std_m=0.002,
        )
        assert not on_ground, k
    # Disarmed: the rest of the step takes it as ground, whatever the state says.
    msg = _telemetry(seq=150, stamp_s=0.6, armed=False, position_m=(0.0, 0.0, 1.0))
    out = contact_decide(state, params, msg, thrust_n=0.0, mass_kg=MASS_KG, dt_s=0.004,
                         floor_z_m=0.0, rotation_rows_world_body=_rows(msg),
                         sample_sigmas=5.55, bias_step_std_mps2=0.05,
                         height_std_m=0.002)  # fmt: skip
    assert out.on_ground


# ---------------------------------------------------------------- filter control


def _obs(tension_n: tuple[float, float, float] | None, thrust_n: float = MASS_KG * G) -> Any:
    from groundstation.tension import TensionObservation

    return TensionObservation(
        tension_world_n=None if tension_n is None else np.array(tension_n),
        on_ground=tension_n is None,
        reason="ok" if tension_n is not None else "low_thrust",
        thrust_axis_world=(0.0, 0.0, 1.0),
        thrust_n=thrust_n,
    )


def test_filter_restarts_once_per_stay_on_the_ground_with_the_liftoff_prior() -> None:
    ctl = FilterControl(TensionFilterParams(mass_kg=MASS_KG))
    rng = np.random.default_rng(0)
    for _ in range(50):
        z = (0.05 + 0.01 * rng.standard_normal(), 0.0, -0.02)
        out = ctl.step(on_ground=False, contact_reason="air", observation=_obs(z), dt_s=0.004)
    assert ctl.filter.initialized and out.estimate is not None and out.finite
    out = ctl.step(on_ground=True, contact_reason="disarmed", observation=_obs(None), dt_s=0.004)
    assert out.tension_world_n == (0.0, 0.0, 0.0) and not out.converged and out.estimate is None
    assert ctl.rested and ctl.prior is True and not ctl.filter.initialized
    trace = ctl.filter.start_trace()
    ctl.step(on_ground=True, contact_reason="disarmed", observation=_obs(None), dt_s=0.004)
    assert not [s for s in trace if s.kind == "reset"], "reset once per stay, not per sample"
    # Lift-off: the first observation updates the prior N(0, σ²), σ derived from the floor
    # load the contact stage lets the drone go at (5 mN at 30 g).
    ratio = contact_mod.ContactParams().push_free_weight_ratio
    assert ctl.liftoff_std_n == (liftoff_prior_std_n(ratio, MASS_KG),) * 3
    out = ctl.step(
        on_ground=False, contact_reason="air", observation=_obs((0.5, 0.0, 0.0)), dt_s=0.004
    )
    assert out.estimate is not None
    assert 0.0 < out.tension_world_n[0] < 0.5  # pulled toward the prior, not the raw sample
    assert out.std_n[0] < ctl.liftoff_std_n[0]


def test_filter_coasts_in_the_air_without_an_observation_and_grows_its_std() -> None:
    ctl = FilterControl(TensionFilterParams(mass_kg=MASS_KG))
    out = ctl.step(on_ground=False, contact_reason="air", observation=_obs(None), dt_s=0.004)
    assert out.estimate is None and out.finite  # nothing to coast yet
    for _ in range(20):
        ctl.step(on_ground=False, contact_reason="air", observation=_obs((0.1, 0, 0)), dt_s=0.004)
    before = ctl.filter.estimate
    assert before is not None
    out = ctl.step(on_ground=False, contact_reason="air", observation=_obs(None), dt_s=0.1)
    assert out.tension_world_n[0] == pytest.approx(float(before.tension_world_n[0]))
    assert out.std_n[0] > float(before.std_n[0])


def test_the_drift_adaptation_reads_the_hover_test_where_one_runs() -> None:
    """With the slow stage (an accelerometer model given) the filter is told the drone
    manoeuvres whenever the hover test does not say it hovers; without it (no test) it is
    never told so. A ramp raises the process noise only where it is told nothing."""
    rng = np.random.default_rng(3)
    outs: dict[str, list[float]] = {}
    for case in ("no_test", "manoeuvring", "hovering"):
        ctl = FilterControl(TensionFilterParams(mass_kg=MASS_KG))
        scales = []
        for k in range(2500):  # 10 s at 250 Hz, a 20 mN/s ramp from 2 s
            z = (0.02 * max(0.0, k * 0.004 - 2.0) + 0.01 * rng.standard_normal(), 0.0, -0.02)
            out = ctl.step(
                on_ground=False,
                contact_reason="air",
                observation=_obs(z),
                dt_s=0.004,
                accel_model_world_n=None if case == "no_test" else z,
                hover_model_world_n=None,  # no thrust balance: only the test's verdict
                hovering=case == "hovering",
            )
            assert out.estimate is not None
            scales.append(out.estimate.process_noise_scale)
        outs[case] = scales
    assert max(outs["no_test"]) > 10.0 and max(outs["hovering"]) > 10.0
    assert max(outs["manoeuvring"]) == 1.0


# ---------------------------------------------------------------- localization inputs


def test_a_reel_angle_is_used_only_while_fresh() -> None:
    angle = AngleObservation(0.3, 0.02)
    assert fresh_angle(angle, received_s=9.0, now_s=10.0, stale_after_s=1.0) is angle
    assert fresh_angle(angle, received_s=8.9, now_s=10.0, stale_after_s=1.0) is None


def test_localize_one_is_localize_with_the_sections_settings() -> None:
    """The stage hands localization the message's inputs and the section's azimuth source
    and motion-capture σ: the very floats of a direct call, and None where it fails."""
    from groundstation.localization import localize

    rng = np.random.default_rng(3)
    for azimuth in ("tension", "mocap"):
        section = LocalizationSection(azimuth=azimuth, mocap_std_m=0.02)
        for _ in range(8):
            t = np.array((0.05 + 0.05 * rng.random(), 0.02 * rng.standard_normal(), -0.02))
            mocap = (0.3, 0.4 + 0.1 * rng.random(), 0.9)
            x = LocalizeIn(t, np.eye(3) * 1e-6, 0.07, 1.6, np.zeros(3), 0.0, None, None, mocap)
            got = localize_one(section, x)
            want = localize(
                t, np.eye(3) * 1e-6, 0.07, 1.6, np.zeros(3), 0.0,
                azimuth=azimuth, mocap_world_m=mocap, mocap_std_m=0.02,
            )  # fmt: skip
            assert got is not None and want is not None
            assert got.position_world_m.tolist() == want.position_world_m.tolist()
            assert got.azimuth_source == azimuth
    bad = LocalizeIn(np.full(3, np.nan), np.eye(3), 0.07, 1.6, np.zeros(3), 0.0, None, None, None)
    assert localize_one(LocalizationSection(), bad) is None


# ---------------------------------------------------------------- follow control


def test_follow_off_only_moves_the_stamp() -> None:
    state = follow_mod.FollowState()
    new, decision = follow_decide(
        state,
        follow_mod.FollowParams(),
        stamp_s=2.5,
        tension_world_n=(0.1, 0.0, 0.0),
        converged=True,
        position=None,
        mocap_world_m=None,
        trusted_without_mocap=True,
        base_world_m=np.zeros(3),
        length_m=1.6,
        floor_z_m=0.0,
        weight_n_per_m=0.07,
        on_ground=False,
    )
    assert decision is None and new.last_stamp_s == 2.5 and new.enabled == state.enabled


def test_follow_holds_an_uncalibrated_drone_without_motion_capture() -> None:
    state = follow_mod.set_enabled(follow_mod.FollowState(), True)
    new, decision = follow_decide(
        state,
        follow_mod.FollowParams(),
        stamp_s=1.0,
        tension_world_n=(0.5, 0.0, 0.0),  # a strong pull
        converged=True,
        position=None,
        mocap_world_m=None,
        trusted_without_mocap=False,
        base_world_m=np.zeros(3),
        length_m=1.6,
        floor_z_m=0.0,
        weight_n_per_m=0.07,
        on_ground=False,
    )
    assert decision is not None and decision.setpoint_world_m is None
    assert decision.stop_reason is None and new.reason == UNTRUSTED_POSITION_REASON


def _refuse(cmd: FollowCommand, **kw: object) -> tuple[str, str] | None:
    args: dict[str, object] = {
        "drone": "cf1",
        "threshold_min_n": 0.02,
        "floor_z_m": 0.0,
        "reach_top_m": 1.6,
        "last_seen_s": 10.0,
        "stale": False,
        "silent_s": 0.1,
        "trusted_position": True,
    }
    args.update(kw)
    return refuse_command(cmd, **args)  # type: ignore[arg-type]


def test_follow_commands_are_refused_for_each_reason_with_its_field() -> None:
    assert _refuse(FollowCommand(enabled=True)) is None
    assert _refuse(FollowCommand(enabled=True, threshold_n=0.01))[0] == "threshold_n"  # type: ignore[index]
    for height in (0.0, 1.6, 2.0):
        got = _refuse(FollowCommand(enabled=True, land_below_m=height))
        assert got is not None and got[0] == "land_below_m"
    assert "no telemetry" in _refuse(FollowCommand(enabled=True), last_seen_s=None)[1]  # type: ignore[index]
    assert "stale" in _refuse(FollowCommand(enabled=True), stale=True)[1]  # type: ignore[index]
    assert (
        "no motion capture"
        in _refuse(  # type: ignore[index]
            FollowCommand(enabled=True), trusted_position=False
        )[1]
    )
    # Switching off is never refused for the drone's state.
    assert _refuse(FollowCommand(enabled=False), stale=True, trusted_position=False) is None


def test_landing_height_is_remembered_while_tug_to_land_is_off() -> None:
    s = FollowCommandState(follow_mod.FollowParams(), follow_mod.FollowState(), None)
    s = apply_command(s, FollowCommand(enabled=True, land_below_m=0.3))
    assert s.params.land_below_m == 0.3 and s.state.enabled
    s = apply_command(s, FollowCommand(enabled=True, land=False))
    assert s.params.land_below_m is None and s.land_below_m_memory == 0.3
    s = apply_command(s, FollowCommand(enabled=True, land=True))
    assert s.params.land_below_m == 0.3


# ---------------------------------------------------------------- the Estimate


def test_estimate_fields_encode_to_the_models_json_and_drop_a_non_finite_position() -> None:
    follow = FollowInfo(enabled=False, active=False, threshold_n=0.1, reason="disabled")
    fields = output.estimate_fields(
        seq=7,
        stamp_s=1.25,
        tension_world_n=[0.03, -0.04, -0.01],
        std_n=[0.001, 0.001, 0.002],
        position=None,
        follow_json=follow.model_dump(),
        on_ground=False,
        converged=True,
        length_m=1.6,
        base_m=(0.0, 0.0, 0.0),
        calibration="none",
        calibration_extrapolated=None,
    )
    payload = output.encode(fields)
    assert payload == Estimate(**{**fields, "follow": follow}).to_json()
    got = json.loads(payload)
    assert got["horizontal_n"] == pytest.approx(0.05) and got["vertical_n"] == 0.01
    with pytest.raises(ValueError, match="non-finite"):
        output.encode({**fields, "length_m": math.nan})


def test_the_liftoff_prior_scales_with_the_weight() -> None:
    """The lift-off prior is half the floor load the contact stage lets a rested drone go
    at (its bound as 2σ): 5 mN at 30 g, as the hand-set value it replaced, and a hundred
    times more for a drone a hundred times heavier; a stricter push bound, a tighter prior."""
    assert liftoff_prior_std_n(0.034, 0.030) == pytest.approx(0.005, rel=1e-3)
    assert liftoff_prior_std_n(0.034, 3.0) == pytest.approx(100 * liftoff_prior_std_n(0.034, 0.03))
    heavy = FilterControl(TensionFilterParams(mass_kg=2.0))
    strict = FilterControl(TensionFilterParams(mass_kg=2.0), push_free_weight_ratio=0.017)
    assert heavy.liftoff_std_n[0] == pytest.approx(2 * strict.liftoff_std_n[0])
    assert heavy.liftoff_std_n[0] == pytest.approx(0.5 * 0.034 * 2.0 * 9.81)
