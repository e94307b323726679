"""Drone scenes as Foxglove's own messages: ``foxglove.SceneUpdate`` and
``foxglove.FrameTransforms`` (foxglove-sdk's classes, protobuf-encoded by the SDK).

Frames: ``world`` (x, y, z up, the motion-capture frame), and per drone ``{drone}/base`` (at
the base exit point) and ``{drone}/body`` (at the drawn position, with the Telemetry's
attitude). Entities per drone, all in ``world``, each replaced whole on every update and
deleted when the scene no longer has it:

==================  =========================================================================
``{drone}/tether``  line strip through the catenary's points (first line); its floor run in
                    a second colour (second line, when part of it rests on the floor)
``{drone}/tension`` arrow at the body along the tension, ``|T| · arrow_m_per_n`` long
``{drone}/body``    the airframe (a flat box with the attitude) and a heading arrow, coloured
                    by mode (flying, following, landing, stopped, on ground)
``{drone}/uncertainty``  ellipsoid of ± 2 σ of the estimated position
``{drone}/base``    a column from the floor to the exit point, and the exit point
``{drone}/mocap``   the motion-capture position (cyan) and a line to the estimate
``{drone}/truth``   the simulator's truth (magenta)
``{drone}/label``   id, mode, |T|
==================  =========================================================================

Every entity carries the Estimate's ``seq`` and ``stamp_s`` as metadata (and the tension
arrow ``tension_n``), so a client can match a scene to the Estimate it was drawn from.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence

import numpy as np
import numpy.typing as npt
from foxglove.messages import (
    ArrowPrimitive,
    Color,
    CubePrimitive,
    FrameTransform,
    FrameTransforms,
    KeyValuePair,
    LinePrimitive,
    LinePrimitiveLineType,
    Point3,
    Pose,
    Quaternion,
    SceneEntity,
    SceneEntityDeletion,
    SceneEntityDeletionType,
    SceneUpdate,
    SpherePrimitive,
    TextPrimitive,
    Timestamp,
    Vector3,
)

from groundstation.foxglove.scene import (
    BASE_RGBA,
    FLOOR_RUN_RGBA,
    MOCAP_RGBA,
    RGBA,
    TENSION_RGBA,
    TETHER_RGBA,
    TRUTH_RGBA,
    DroneScene,
)

__all__ = [
    "ENTITY_KINDS",
    "SCENE_TOPIC",
    "TRANSFORMS_TOPIC",
    "WORLD_FRAME",
    "arrow_orientation",
    "frame_transforms",
    "scene_update",
    "timestamp",
]

SCENE_TOPIC = "scene"
"""The ``foxglove.SceneUpdate`` topic (every drone's entities), live and in recordings."""
TRANSFORMS_TOPIC = "tf"
"""The ``foxglove.FrameTransforms`` topic, live and in recordings."""
WORLD_FRAME = "world"
ENTITY_KINDS = ("tether", "tension", "body", "uncertainty", "base", "mocap", "truth", "label")
"""The entities of each drone, ``{drone}/{kind}``."""
BODY_SIZE_M = (0.18, 0.18, 0.03)
"""The 92 mm airframe drawn twice life size (as the dashboard draws it), m."""
TETHER_THICKNESS_M = 0.006
ARROW_SHAFT_M = 0.012
ARROW_HEAD_M = (0.04, 0.03)
"""Head length and diameter of the tension arrow, m."""
LABEL_HEIGHT_M = 0.12


def timestamp(stamp_ns: int) -> Timestamp:
    """A Foxglove Timestamp of ``stamp_ns`` nanoseconds since the Unix epoch."""
    sec, nsec = divmod(int(stamp_ns), 1_000_000_000)
    return Timestamp(sec, nsec)


def _color(rgba: RGBA) -> Color:
    return Color(r=rgba[0], g=rgba[1], b=rgba[2], a=rgba[3])


def _vec(v: Sequence[float]) -> Vector3:
    return Vector3(x=float(v[0]), y=float(v[1]), z=float(v[2]))


def _pose(position_m: Sequence[float], wxyz: Sequence[float] = (1.0, 0.0, 0.0, 0.0)) -> Pose:
    return Pose(
        position=_vec(position_m),
        orientation=Quaternion(
            w=float(wxyz[0]), x=float(wxyz[1]), y=float(wxyz[2]), z=float(wxyz[3])
        ),
    )


def _points(pts: npt.NDArray[np.float64]) -> list[Point3]:
    return [Point3(x=float(x), y=float(y), z=float(z)) for x, y, z in pts.tolist()]


def arrow_orientation(direction: Sequence[float]) -> tuple[float, float, float, float]:
    """The unit quaternion (w, x, y, z) that turns +x (Foxglove's arrow axis) onto the unit
    vector ``direction``: the half-way rotation, q = (1 + x·d, x × d) normalised."""
    dx, dy, dz = (float(c) for c in direction)
    w, x, y, z = 1.0 + dx, 0.0, -dz, dy  # x × d = (0, −d_z, d_y)
    norm = math.sqrt(w * w + x * x + y * y + z * z)
    if norm < 1e-9:  # d = −x: half a turn about z
        return (0.0, 0.0, 0.0, 1.0)
    return (w / norm, x / norm, y / norm, z / norm)


def _metadata(scene: DroneScene, **extra: str) -> list[KeyValuePair]:
    pairs = {
        "seq": "" if scene.seq is None else str(scene.seq),
        "stamp_s": "" if scene.stamp_s is None else repr(scene.stamp_s),
        "mode": scene.mode,
        **extra,
    }
    return [KeyValuePair(key=k, value=v) for k, v in pairs.items()]


def _entities(scene: DroneScene, stamp: Timestamp) -> dict[str, SceneEntity]:
    """The drone's entities by kind (kinds without anything to draw are absent)."""
    d = scene.drone_id

    def entity(kind: str, **primitives: object) -> SceneEntity:
        extra = {}
        if kind == "tension" and scene.arrow is not None:
            extra["tension_n"] = repr(scene.arrow.tension_n)
        return SceneEntity(
            timestamp=stamp,
            frame_id=WORLD_FRAME,
            id=f"{d}/{kind}",
            metadata=_metadata(scene, **extra),
            **primitives,  # type: ignore[arg-type]
        )

    out: dict[str, SceneEntity] = {}
    if scene.tether_m is not None:
        lines = [
            LinePrimitive(
                type=LinePrimitiveLineType.LineStrip,
                thickness=TETHER_THICKNESS_M,
                points=_points(scene.tether_m),
                color=_color(TETHER_RGBA),
            )
        ]
        if scene.floor_run_m is not None:
            lines.append(
                LinePrimitive(
                    type=LinePrimitiveLineType.LineStrip,
                    thickness=1.5 * TETHER_THICKNESS_M,
                    points=_points(scene.floor_run_m),
                    color=_color(FLOOR_RUN_RGBA),
                )
            )
        out["tether"] = entity("tether", lines=lines)
    if scene.arrow is not None:
        a = scene.arrow
        head_m = min(ARROW_HEAD_M[0], 0.5 * a.length_m)
        out["tension"] = entity(
            "tension",
            arrows=[
                ArrowPrimitive(
                    pose=_pose(a.start_m, arrow_orientation(a.direction)),
                    shaft_length=a.length_m - head_m,
                    shaft_diameter=ARROW_SHAFT_M,
                    head_length=head_m,
                    head_diameter=ARROW_HEAD_M[1],
                    color=_color(TENSION_RGBA),
                )
            ],
        )
    if scene.body_m is not None:
        body_pose = _pose(scene.body_m, scene.quat_wxyz)
        out["body"] = entity(
            "body",
            cubes=[
                CubePrimitive(pose=body_pose, size=_vec(BODY_SIZE_M), color=_color(scene.body_rgba))
            ],
            arrows=[  # heading: body +x
                ArrowPrimitive(
                    pose=body_pose,
                    shaft_length=0.08,
                    shaft_diameter=0.008,
                    head_length=0.03,
                    head_diameter=0.02,
                    color=_color(scene.body_rgba),
                )
            ],
        )
        label_at = (scene.body_m[0], scene.body_m[1], scene.body_m[2] + LABEL_HEIGHT_M)
        out["label"] = entity(
            "label",
            texts=[
                TextPrimitive(
                    pose=_pose(label_at),
                    billboard=True,
                    font_size=14.0,
                    scale_invariant=True,
                    color=_color((0.1, 0.1, 0.1, 1.0)),
                    text=scene.label,
                )
            ],
        )
    if scene.ellipsoid_center_m is not None and scene.ellipsoid_size_m is not None:
        r, g, b, _ = scene.body_rgba
        out["uncertainty"] = entity(
            "uncertainty",
            spheres=[
                SpherePrimitive(
                    pose=_pose(scene.ellipsoid_center_m),
                    size=_vec(scene.ellipsoid_size_m),
                    color=_color((r, g, b, 0.2)),
                )
            ],
        )
    bx, by, bz = scene.base_m
    height_m = max(0.01, bz - scene.floor_z_m)
    out["base"] = entity(
        "base",
        cubes=[
            CubePrimitive(
                pose=_pose((bx, by, scene.floor_z_m + height_m / 2.0)),
                size=_vec((0.05, 0.05, height_m)),
                color=_color(BASE_RGBA),
            )
        ],
        spheres=[
            SpherePrimitive(
                pose=_pose(scene.base_m), size=_vec((0.04, 0.04, 0.04)), color=_color(BASE_RGBA)
            )
        ],
    )
    if scene.mocap_m is not None:
        lines = []
        if scene.body_m is not None and scene.body_source == "estimate":
            lines.append(
                LinePrimitive(
                    type=LinePrimitiveLineType.LineList,
                    thickness=0.003,
                    points=_points(np.array([scene.body_m, scene.mocap_m], dtype=np.float64)),
                    color=_color(MOCAP_RGBA),
                )
            )
        out["mocap"] = entity(
            "mocap",
            spheres=[
                SpherePrimitive(
                    pose=_pose(scene.mocap_m), size=_vec((0.03,) * 3), color=_color(MOCAP_RGBA)
                )
            ],
            lines=lines,
        )
    if scene.truth_m is not None:
        out["truth"] = entity(
            "truth",
            spheres=[
                SpherePrimitive(
                    pose=_pose(scene.truth_m), size=_vec((0.025,) * 3), color=_color(TRUTH_RGBA)
                )
            ],
        )
    return out


def scene_update(scenes: Iterable[DroneScene], stamp_ns: int) -> SceneUpdate:
    """A ``foxglove.SceneUpdate`` replacing every entity of these drones.

    Entities a drone has no data for this time (an arrow on the ground, a position not yet
    determined) are deleted, so nothing stale stays drawn.

    Args:
        scenes: the drones' scenes.
        stamp_ns: the entities' timestamp, ns since the Unix epoch.
    """
    stamp = timestamp(stamp_ns)
    entities: list[SceneEntity] = []
    deletions: list[SceneEntityDeletion] = []
    for scene in scenes:
        drawn = _entities(scene, stamp)
        entities.extend(drawn.values())
        deletions.extend(
            SceneEntityDeletion(
                timestamp=stamp,
                type=SceneEntityDeletionType.MatchingId,
                id=f"{scene.drone_id}/{kind}",
            )
            for kind in ENTITY_KINDS
            if kind not in drawn
        )
    return SceneUpdate(deletions=deletions, entities=entities)


def frame_transforms(scenes: Iterable[DroneScene], stamp_ns: int) -> FrameTransforms:
    """``world`` → ``{drone}/base`` and ``world`` → ``{drone}/body`` for each drone (the body
    only once it has a position), as a ``foxglove.FrameTransforms``."""
    stamp = timestamp(stamp_ns)
    transforms = []
    identity = Quaternion(w=1.0, x=0.0, y=0.0, z=0.0)
    for scene in scenes:
        transforms.append(
            FrameTransform(
                timestamp=stamp,
                parent_frame_id=WORLD_FRAME,
                child_frame_id=f"{scene.drone_id}/base",
                translation=_vec(scene.base_m),
                rotation=identity,
            )
        )
        if scene.body_m is not None:
            w, x, y, z = scene.quat_wxyz
            transforms.append(
                FrameTransform(
                    timestamp=stamp,
                    parent_frame_id=WORLD_FRAME,
                    child_frame_id=f"{scene.drone_id}/body",
                    translation=_vec(scene.body_m),
                    rotation=Quaternion(w=w, x=x, y=y, z=z),
                )
            )
    return FrameTransforms(transforms=transforms)
