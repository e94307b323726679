"""The Foxglove scene: built from an Estimate and the configuration (no server), encoded in
Foxglove's own schemas and decoded back with Google's protobuf runtime from the schema
foxglove-sdk publishes, and the scene channels of an offline replay."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from typing import Any

import numpy as np
import pytest
from foxglove.messages import FrameTransforms, SceneUpdate

from groundstation import catenary
from groundstation.config import Settings
from groundstation.foxglove.offline import SceneTap
from groundstation.foxglove.scene import (
    ELLIPSOID_SIGMAS,
    MOCAP_RGBA,
    MODE_RGBA,
    TRUTH_RGBA,
    DroneInputs,
    build_drone_scene,
    drone_mode,
)
from groundstation.foxglove.schemas import (
    ENTITY_KINDS,
    SCENE_TOPIC,
    TRANSFORMS_TOPIC,
    arrow_orientation,
    frame_transforms,
    scene_update,
)
from groundstation.messages import Estimate, FollowInfo
from tests.foxglove_decode import message_class, metadata, rotate_x

PARAMS = Settings().for_drone("cf1")


def _estimate(**overrides: Any) -> Estimate:
    fields: dict[str, Any] = {
        "seq": 7,
        "stamp_s": 1.5,
        "tension_n": (0.09, -0.12, -0.2),
        "tension_std_n": (0.01, 0.01, 0.005),
        "horizontal_n": 0.15,
        "vertical_n": 0.2,
        "position_m": (0.8, 0.1, 1.0),
        "follow": FollowInfo(enabled=False, active=False, threshold_n=0.15),
        "position_std_m": (0.02, 0.03, 0.01),
        "length_m": 1.6,
        "base_m": (0.1, -0.2, 0.754),
    }
    fields.update(overrides)
    return Estimate(**fields)


def test_the_scene_builder_loads_without_foxglove_or_zenoh() -> None:
    code = (
        "import sys, groundstation.foxglove.scene\n"
        "bad = [m for m in ('foxglove', 'zenoh', 'viser') if m in sys.modules]\n"
        "assert not bad, bad\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True)


def test_the_tether_is_the_catenary_through_base_and_estimate() -> None:
    est = _estimate()
    scene = build_drone_scene(DroneInputs("cf1", est), PARAMS)
    assert scene.body_m == est.position_m and scene.body_source == "estimate"
    assert scene.base_m == est.base_m and scene.length_m == est.length_m
    expected = catenary.tether_points(
        est.base_m, est.position_m, 1.6, floor_z_m=PARAMS.base.floor_z_m, n=64
    )
    assert scene.tether_m is not None
    np.testing.assert_allclose(scene.tether_m, expected, rtol=0, atol=1e-12)
    # It sags: a hanging tether's lowest point is below both ends.
    assert scene.tether_m[:, 2].min() < min(est.base_m[2], est.position_m[2]) - 0.05
    assert scene.floor_run_m is None


def test_a_slack_tether_has_its_floor_run() -> None:
    est = _estimate(position_m=(0.5, 0.0, 0.3), base_m=(0.0, 0.0, 0.754), length_m=3.0)
    scene = build_drone_scene(DroneInputs("cf1", est), PARAMS)
    assert scene.floor_run_m is not None and len(scene.floor_run_m) >= 2
    np.testing.assert_allclose(scene.floor_run_m[:, 2], PARAMS.base.floor_z_m, atol=1e-3)
    expected = catenary.tether_points(est.base_m, est.position_m, 3.0, floor_z_m=0.0, n=64)
    np.testing.assert_allclose(scene.tether_m, expected, atol=1e-12)


def test_the_arrow_is_the_tension_scaled_in_newtons() -> None:
    est = _estimate()
    scene = build_drone_scene(DroneInputs("cf1", est), PARAMS, arrow_m_per_n=4.0)
    norm_n = math.dist(est.tension_n, (0.0, 0.0, 0.0))
    assert scene.arrow is not None
    assert scene.arrow.start_m == est.position_m
    assert scene.arrow.tension_n == pytest.approx(norm_n)
    assert scene.arrow.length_m == pytest.approx(4.0 * norm_n)
    np.testing.assert_allclose(scene.arrow.direction, np.divide(est.tension_n, norm_n))


def test_the_ellipsoid_spans_two_sigma_and_is_clipped() -> None:
    scene = build_drone_scene(DroneInputs("cf1", _estimate()), PARAMS)
    assert scene.ellipsoid_center_m == (0.8, 0.1, 1.0)
    assert scene.ellipsoid_size_m == pytest.approx(
        tuple(2 * ELLIPSOID_SIGMAS * s for s in (0.02, 0.03, 0.01))
    )
    tiny = build_drone_scene(
        DroneInputs("cf1", _estimate(position_std_m=(1e-5, 10.0, 0.01))), PARAMS
    )
    assert tiny.ellipsoid_size_m == pytest.approx((0.005, 3.0, 0.04))


def test_on_the_ground_there_is_no_arrow_and_the_colour_says_so() -> None:
    est = _estimate(on_ground=True, tension_n=(0.0, 0.0, 0.0))
    scene = build_drone_scene(DroneInputs("cf1", est), PARAMS)
    assert scene.arrow is None and scene.mode == "on_ground"
    assert scene.body_rgba == MODE_RGBA["on_ground"]


@pytest.mark.parametrize(
    ("follow", "mode"),
    [
        ({"enabled": False}, "flying"),
        ({"enabled": True}, "following"),
        ({"enabled": True, "land_below_m": 0.3, "landing_armed": True}, "landing"),
        ({"enabled": False, "stopped": True}, "stopped"),
    ],
)
def test_follow_and_landing_state_is_the_drones_colour(follow: dict[str, Any], mode: str) -> None:
    est = _estimate(follow=FollowInfo(active=False, threshold_n=0.15, **follow))
    assert drone_mode(est) == mode
    assert build_drone_scene(DroneInputs("cf1", est), PARAMS).body_rgba == MODE_RGBA[mode]  # type: ignore[index]
    assert len(set(MODE_RGBA.values())) == len(MODE_RGBA)


def test_motion_capture_and_truth_stand_apart_from_every_mode_colour() -> None:
    # The marker beside a following drone must not read as the drone: RGB distance of at
    # least 0.25 from every body colour (the marker was the following green's near twin).
    for name, marker in (("mocap", MOCAP_RGBA), ("truth", TRUTH_RGBA)):
        for mode, body in MODE_RGBA.items():
            distance = math.dist(marker[:3], body[:3])
            assert distance >= 0.25, (name, mode, distance)
    assert math.dist(MOCAP_RGBA[:3], TRUTH_RGBA[:3]) >= 0.25


def test_without_a_position_the_drone_is_drawn_at_motion_capture() -> None:
    est = _estimate(position_m=None, position_std_m=None)
    inputs = DroneInputs("cf1", est, mocap_m=(0.3, 0.2, 0.9), truth_m=(0.31, 0.2, 0.9))
    scene = build_drone_scene(inputs, PARAMS)
    assert scene.body_m == (0.3, 0.2, 0.9) and scene.body_source == "mocap"
    assert scene.ellipsoid_center_m is None
    assert "position undetermined" in scene.label
    nothing = build_drone_scene(DroneInputs("cf1"), PARAMS)
    assert nothing.body_m is None and nothing.tether_m is None and nothing.mode == "no_estimate"
    assert nothing.base_m == PARAMS.base.position_m


@pytest.mark.parametrize("seed", range(5))
def test_the_arrow_orientation_turns_x_onto_the_tension(seed: int) -> None:
    rng = np.random.default_rng(seed)
    for d in [*rng.normal(size=(20, 3)), (-1.0, 0.0, 0.0), (1.0, 0.0, 0.0)]:
        d = np.asarray(d) / np.linalg.norm(d)
        w, x, y, z = arrow_orientation(d)

        class Q:  # the protobuf Quaternion's field names
            pass

        q = Q()
        q.w, q.x, q.y, q.z = w, x, y, z  # type: ignore[attr-defined]
        np.testing.assert_allclose(rotate_x(q), d, atol=1e-12)


def _decode(message: Any) -> Any:
    schema = type(message).get_schema()
    assert schema.encoding == "protobuf"
    return message_class(schema.name, schema.data).FromString(message.encode())


def test_the_scene_decodes_with_foxgloves_schema() -> None:
    est = _estimate()
    scene = build_drone_scene(
        DroneInputs("cf1", est, quat_wxyz=(1.0, 0.0, 0.0, 0.0), mocap_m=(0.81, 0.1, 1.0)), PARAMS
    )
    update = _decode(scene_update([scene], 1_700_000_000_123_456_789))
    by_id = {e.id: e for e in update.entities}
    assert set(by_id) == {
        "cf1/tether",
        "cf1/tension",
        "cf1/body",
        "cf1/uncertainty",
        "cf1/base",
        "cf1/mocap",
        "cf1/label",
    }
    assert [d.id for d in update.deletions] == ["cf1/truth"]  # nothing stale stays drawn
    tether = by_id["cf1/tether"]
    assert tether.frame_id == "world" and metadata(tether)["seq"] == "7"
    assert tether.timestamp.seconds == 1_700_000_000 and tether.timestamp.nanos == 123_456_789
    points = np.array([(p.x, p.y, p.z) for p in tether.lines[0].points])
    assert scene.tether_m is not None
    np.testing.assert_array_equal(points, scene.tether_m)
    (arrow,) = by_id["cf1/tension"].arrows
    norm_n = math.dist(est.tension_n, (0.0, 0.0, 0.0))
    assert (arrow.pose.position.x, arrow.pose.position.y, arrow.pose.position.z) == est.position_m
    np.testing.assert_allclose(rotate_x(arrow.pose.orientation), np.divide(est.tension_n, norm_n))
    assert arrow.shaft_length + arrow.head_length == pytest.approx(4.0 * norm_n)
    assert float(metadata(by_id["cf1/tension"])["tension_n"]) == pytest.approx(norm_n)
    (ellipsoid,) = by_id["cf1/uncertainty"].spheres
    assert (ellipsoid.size.x, ellipsoid.size.y, ellipsoid.size.z) == pytest.approx(
        scene.ellipsoid_size_m
    )

    tfs = _decode(frame_transforms([scene], 1_700_000_000_000_000_000))
    frames = {(t.parent_frame_id, t.child_frame_id): t for t in tfs.transforms}
    assert set(frames) == {("world", "cf1/base"), ("world", "cf1/body")}
    body = frames[("world", "cf1/body")].translation
    assert (body.x, body.y, body.z) == est.position_m


def test_an_update_deletes_what_a_drone_no_longer_has() -> None:
    on_ground = build_drone_scene(
        DroneInputs("cf2", _estimate(on_ground=True, position_m=None, position_std_m=None)), PARAMS
    )
    update = _decode(scene_update([on_ground], 0))
    assert {e.id for e in update.entities} == {"cf2/base"}
    assert {d.id for d in update.deletions} == {f"cf2/{k}" for k in ENTITY_KINDS} - {"cf2/base"}


def test_the_offline_tap_draws_at_its_rate_of_log_time() -> None:
    settings = Settings.model_validate({"foxglove": {"scene_rate_hz": 10.0}})
    tap = SceneTap(settings)
    t0 = 1_700_000_000 * 10**9
    out = []
    for i in range(250):  # one second at 250 Hz
        est = _estimate(seq=i, stamp_s=i * 0.004)
        out += tap.after("tether/cf1/estimate", est.model_dump_json().encode(), t0 + i * 4_000_000)
        out += tap.after("replay/original/tether/cf1/estimate", b"{}", t0 + i * 4_000_000)
    scenes = [m for m in out if m.topic == SCENE_TOPIC]
    tfs = [m for m in out if m.topic == TRANSFORMS_TOPIC]
    assert len(scenes) == len(tfs) == 10  # 10 Hz over 1 s
    times = [m.log_time_ns for m in scenes]
    assert times == sorted(times) and times[0] == t0
    np.testing.assert_allclose(np.diff(times), 100_000_000, atol=4_000_000)
    assert scenes[0].schema.name == "foxglove.SceneUpdate"
    assert tfs[0].schema.name == "foxglove.FrameTransforms"
    last = message_class("foxglove.SceneUpdate", scenes[-1].schema.data).FromString(scenes[-1].data)
    seqs = {metadata(e)["seq"] for e in last.entities}
    assert seqs == {"225"}  # drawn from the estimate written just before it
    assert SceneUpdate.get_schema().data == scenes[0].schema.data
    assert FrameTransforms.get_schema().data == tfs[0].schema.data
    # The estimates after the last scene are drawn at the next message due; after that,
    # nothing new for the drone: nothing written.
    late = tap.after("tether/cf1/status", json.dumps({}).encode(), t0 + 2 * 10**9)
    assert [m.topic for m in late] == [TRANSFORMS_TOPIC, SCENE_TOPIC]
    assert tap.after("tether/cf1/status", json.dumps({}).encode(), t0 + 3 * 10**9) == []


def test_the_layout_shows_what_is_published() -> None:
    """docs/foxglove_layout.json: its 3D panel shows the scene and transform topics, its plot
    and message panels read fields the contract's models have."""
    from pathlib import Path

    from groundstation.messages import Truth

    layout = json.loads(
        (Path(__file__).resolve().parents[1] / "docs" / "foxglove_layout.json").read_text()
    )
    panels = layout["configById"]
    three_d = next(v for k, v in panels.items() if k.startswith("3D!"))
    assert set(three_d["topics"]) == {SCENE_TOPIC, TRANSFORMS_TOPIC}
    assert three_d["followTf"] == "world"
    plot = next(v for k, v in panels.items() if k.startswith("Plot!"))
    models = {"estimate": Estimate, "truth": Truth}
    for series in plot["paths"]:
        topic, path = series["value"].split(".", 1)
        assert topic.startswith("tether/cf1/")
        assert path.split("[")[0] in models[topic.rsplit("/", 1)[1]].model_fields, series
    raw = next(v for k, v in panels.items() if k.startswith("RawMessages!"))
    assert raw["topicPath"] == "tether/cf1/estimate"

    def leaves(node: Any) -> list[str]:
        return [node] if isinstance(node, str) else leaves(node["first"]) + leaves(node["second"])

    assert sorted(leaves(layout["layout"])) == sorted(panels)
