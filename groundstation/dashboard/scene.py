"""The 3D scene (viser): floor, world axes, and per drone its quadrotor, tether, tension arrow,
uncertainty, motion-capture marker, trail, base and one label.

Shared by every browser (viser's scene is server-wide). Only changes are sent: each
assignment to a viser handle is a websocket message, so visibility and label texts are
cached. A stale drone is drawn faded (grey tether, translucent body, no arrow); a forgotten
one is removed.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import numpy.typing as npt
import viser

from groundstation.catenary import tether_points as catenary_tether_points
from groundstation.config import Settings
from groundstation.dashboard.model import DroneState, tension_norm_n

__all__ = [
    "ARROW_M_PER_N",
    "LABEL_CLEARANCE_M",
    "LABEL_STEP_M",
    "PANEL_PX",
    "Scene",
    "camera_framing",
    "label_tiers",
    "load_quadrotor_mesh",
    "panel_fraction",
    "polyline_segments",
    "project",
    "tension_arrow",
    "tether_points",
]

_log = logging.getLogger(__name__)

ARROW_M_PER_N = 4.0
"""Drawn length of the tension arrow per newton."""
QUAD_DRAW_SCALE = 2.0
"""The 92 mm quadrotor is drawn this much larger than life so that it reads at room scale."""
LABEL_HEIGHT_M = 0.09
"""A drone's label sits this far above its body."""
LABEL_CLEARANCE_M = 0.6
"""Drones closer than this (horizontally) get their labels stacked at different heights."""
LABEL_STEP_M = 0.2
"""Height between stacked labels (three lines of screen-sized text at room distances)."""
WORLD_AXES_M = 0.3
FADED_OPACITY = 0.25

PALETTE: tuple[tuple[int, int, int], ...] = (
    (34, 139, 230),
    (240, 140, 0),
    (55, 178, 77),
    (174, 62, 201),
    (224, 49, 49),
    (16, 152, 173),
    (247, 103, 7),
    (112, 72, 232),
)
_TETHER_RGB = (40, 40, 40)
_STALE_RGB = (190, 190, 190)
_FLOOR_RUN_RGB = (150, 110, 60)
_TENSION_RGB = (224, 49, 49)
_MOCAP_RGB = (47, 158, 68)
_TRUTH_RGB = (134, 142, 150)
_BASE_RGB = (134, 142, 150)

_MESH_PATHS = (
    # Shipped with the package if package-data carries it, else the repository's web/.
    Path(__file__).resolve().parent.parent / "assets" / "quadrotor.stl",
    Path(__file__).resolve().parent.parent.parent / "web" / "quadrotor.stl",
)

Vec3 = tuple[float, float, float]


# --------------------------------------------------------------------------------------------
# Geometry for drawing.
# --------------------------------------------------------------------------------------------


def tether_points(
    base_world_m: Sequence[float],
    drone_world_m: Sequence[float],
    length_m: float,
    floor_z_m: float = -math.inf,
    n: int = 64,
) -> npt.NDArray[np.float64]:
    """Points (n, 3) along the tether for drawing, world frame, metres.

    The catenary with its floor run (``groundstation.catenary.tether_points``); an end a
    little below the floor (estimate noise) is drawn on it. Where the catenary has no curve
    for these inputs (it raises for an end below the floor or a bad length), the chord.
    """
    base = np.asarray(base_world_m, dtype=np.float64)
    drone = np.asarray(drone_world_m, dtype=np.float64)
    if math.isfinite(floor_z_m):
        base = np.array([base[0], base[1], max(base[2], floor_z_m)])
        drone = np.array([drone[0], drone[1], max(drone[2], floor_z_m)])
    try:
        return catenary_tether_points(base, drone, float(length_m), floor_z_m=floor_z_m, n=n)
    except ValueError:  # CatenaryError: drawn as the chord rather than not at all
        s = np.linspace(0.0, 1.0, n)[:, None]
        return base + s * (drone - base)


def polyline_segments(points: npt.ArrayLike) -> npt.NDArray[np.float32]:
    """Line segments (N-1, 2, 3) joining consecutive points (N, 3)."""
    pts = np.asarray(points, dtype=np.float32)
    if len(pts) < 2:
        return np.zeros((1, 2, 3), dtype=np.float32)
    return np.stack([pts[:-1], pts[1:]], axis=1)


def tension_arrow(
    position_m: Sequence[float], tension_n: Sequence[float], m_per_n: float = ARROW_M_PER_N
) -> npt.NDArray[np.float32]:
    """The arrow (1, 2, 3) from the drone along the tension, ``m_per_n`` metres per newton."""
    start = np.asarray(position_m, dtype=np.float32)
    end = start + np.asarray(tension_n, dtype=np.float32) * np.float32(m_per_n)
    return np.stack([start, end])[None]


PANEL_PX = 400.0
"""Width of viser's "large" control panel (24 em × 16 px) plus its margin, CSS pixels: it
floats over the right of the 3D view."""
VIEW_DIRECTION = (-0.35, -1.0, 0.55)
"""The framing camera looks from the front-left, above, along minus this."""
VIEW_DIRECTION_ALONG_Y = (-1.0, -0.35, 0.55)
"""The same turned a quarter, for a set-up laid out along y (config/sim.toml's bases 3 m
apart in y): seen from the front, its drones would stand behind one another."""


def panel_fraction(image_width_px: float | None) -> float:
    """The share of the canvas' width the control panel covers, for framing.

    viser reports the canvas' drawing-buffer width, device pixels (CSS pixels × an adaptive
    device-pixel ratio, unknown here), so the panel's share cannot be known exactly; it is
    taken as at least 0.3 (400 CSS px of a 1280 px screen, or of a HiDPI screen whose buffer
    is wider) and at most 0.5.
    """
    if image_width_px is None or image_width_px <= 0.0:
        return 0.32
    return float(np.clip(PANEL_PX / image_width_px, 0.3, 0.5))


def _view_basis(
    extent_m: npt.NDArray[np.float64],
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """(forward, right, up) of the framing camera for points of this (x, y, z) extent."""
    along_y = extent_m[1] > 1.5 * extent_m[0] and extent_m[1] > 1.0
    forward = -np.asarray(VIEW_DIRECTION_ALONG_Y if along_y else VIEW_DIRECTION, dtype=float)
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, (0.0, 0.0, 1.0))
    right /= np.linalg.norm(right)
    return forward, right, np.cross(right, forward)


def camera_framing(
    points_m: npt.ArrayLike,
    fov_rad: float = math.radians(60.0),
    *,
    aspect: float = 1.6,
    covered_right: float = 0.0,
    margin: float = 0.12,
    min_radius_m: float = 0.6,
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """Camera (position, look_at) that frames all points in the uncovered part of the view.

    Seen from the front-left, above (:data:`VIEW_DIRECTION`; from the side,
    :data:`VIEW_DIRECTION_ALONG_Y`, for points spread along y). The nearest camera is found
    for which every point projects inside the view less the right ``covered_right`` of its
    width (where the control panel floats) and less ``margin`` of each half-extent (room for
    labels), and which is no nearer than a sphere round the points needs to fit the view's
    height (with 15 % to spare); look_at is the point the camera looks at, at that distance.

    Args:
        points_m: (k, 3) world points (bases, drones, motion-capture markers), k ≥ 1.
        fov_rad: vertical field of view.
        aspect: the view's width / height.
        covered_right: share of the view's width hidden on the right, [0, 0.9].
        margin: share of each half-extent kept free at the edges.
        min_radius_m: frame at least a sphere of this radius.

    Returns:
        (position, look_at), world frame, metres.
    """
    pts = np.atleast_2d(np.asarray(points_m, dtype=np.float64))
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    center = (lo + hi) / 2.0
    q = pts - center
    forward, right, up = _view_basis(hi - lo)
    tan_v = math.tan(fov_rad / 2.0)
    tan_h = tan_v * aspect
    # The free window in normalised device coordinates ([-1, 1] across the whole view).
    x_lo, x_hi = -1.0 + margin, 1.0 - 2.0 * float(np.clip(covered_right, 0.0, 0.9)) - margin
    y_lo, y_hi = -1.0 + margin, 1.0 - margin
    qx, qy, qz = q @ right, q @ up, q @ forward

    def window(d: float) -> tuple[float, float, float, float] | None:
        # Camera at center + a·right + b·up − d·forward: a point's depth is qz + d, its
        # offsets qx − a and qy − b; it is inside when x_lo ≤ (qx − a)/(z·tan_h) ≤ x_hi.
        z = qz + d
        if np.any(z <= 0.05):
            return None
        a_lo = float(np.max(qx - x_hi * tan_h * z))
        a_hi = float(np.min(qx - x_lo * tan_h * z))
        b_lo = float(np.max(qy - y_hi * tan_v * z))
        b_hi = float(np.min(qy - y_lo * tan_v * z))
        if a_lo > a_hi or b_lo > b_hi:
            return None
        return a_lo, a_hi, b_lo, b_hi

    # Never nearer than a sphere round the points fits the view's height with room to
    # spare: the drones move after the framing (a take-off), and a camera just in front of
    # one near point would make it huge.
    radius_m = max(min_radius_m, 0.5 * float(np.linalg.norm(hi - lo)))
    near_m = max(1.15 * radius_m / math.sin(fov_rad / 2.0), float(np.max(-qz)) + 0.5)
    far_m = near_m
    while window(far_m) is None:  # widening with distance: some distance fits
        far_m *= 2.0
    if window(near_m) is None:
        for _ in range(40):
            mid_m = 0.5 * (near_m + far_m)
            if window(mid_m) is None:
                near_m = mid_m
            else:
                far_m = mid_m
        near_m = far_m
    fit = window(near_m)
    assert fit is not None
    a_m, b_m = 0.5 * (fit[0] + fit[1]), 0.5 * (fit[2] + fit[3])
    look_at = center + a_m * right + b_m * up
    return look_at - near_m * forward, look_at


def project(
    points_m: npt.ArrayLike,
    position_m: Sequence[float],
    look_at_m: Sequence[float],
    fov_rad: float,
    aspect: float,
) -> npt.NDArray[np.float64]:
    """Normalised device coordinates (k, 2) of points seen by a camera with z up.

    x from −1 (left edge) to 1 (right edge), y from −1 (bottom) to 1 (top).
    """
    pts = np.atleast_2d(np.asarray(points_m, dtype=np.float64))
    position = np.asarray(position_m, dtype=np.float64)
    forward = np.asarray(look_at_m, dtype=np.float64) - position
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, (0.0, 0.0, 1.0))
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    rel = pts - position
    z = rel @ forward
    tan_v = math.tan(fov_rad / 2.0)
    return np.stack([(rel @ right) / (z * tan_v * aspect), (rel @ up) / (z * tan_v)], axis=1)


def label_tiers(positions_m: Mapping[str, Sequence[float]]) -> dict[str, int]:
    """A stacking tier per drone so that labels of neighbouring drones do not overlap.

    Drones are taken in id order; each gets the lowest tier not used by a drone already
    placed within :data:`LABEL_CLEARANCE_M` horizontally whose label would be less than
    :data:`LABEL_STEP_M` above or below. A label is drawn ``tier × LABEL_STEP_M`` above the
    usual height, so neighbours' labels are at least one step apart in height.

    Args:
        positions_m: drone id → drawn body position, world frame, metres.

    Returns:
        drone id → tier (0 for a drone with no close neighbour).
    """
    placed: list[tuple[npt.NDArray[np.float64], int]] = []
    tiers: dict[str, int] = {}
    for drone_id in sorted(positions_m):
        p = np.asarray(positions_m[drone_id], dtype=np.float64)
        near = [
            (q, tier_q)
            for q, tier_q in placed
            if math.hypot(p[0] - q[0], p[1] - q[1]) < LABEL_CLEARANCE_M
        ]
        tier = 0
        # Compare label heights, not bodies: a neighbour's label may already be raised.
        while any(
            abs(p[2] + tier * LABEL_STEP_M - (q[2] + tier_q * LABEL_STEP_M)) < LABEL_STEP_M
            for q, tier_q in near
        ):
            tier += 1
        tiers[drone_id] = tier
        placed.append((p, tier))
    return tiers


def load_quadrotor_mesh(
    path: Path | None = None,
) -> tuple[npt.NDArray[np.float32], npt.NDArray[np.uint32]]:
    """Vertices (V, 3) and faces (F, 3) of the quadrotor drawn for each drone, body frame, m.

    Reads the binary STL written by ``web/make_quadrotor.py``: ``path``, else
    ``groundstation/assets/quadrotor.stl`` (if packaged), else the repository's
    ``web/quadrotor.stl``; without any (a wheel without the asset) a plain cross of two bars
    stands in.
    """
    candidates = [path] if path is not None else list(_MESH_PATHS)
    for candidate in candidates:
        try:
            data = candidate.read_bytes()
        except OSError:
            continue
        if len(data) < 84:
            continue
        count = int(np.frombuffer(data, dtype="<u4", count=1, offset=80)[0])
        if len(data) != 84 + 50 * count or count == 0:
            _log.warning("%s is not a binary STL; drawing a plain cross", candidate)
            continue
        record = np.dtype([("normal", "<f4", (3,)), ("vertices", "<f4", (3, 3)), ("attr", "<u2")])
        tris = np.frombuffer(data, dtype=record, count=count, offset=84)["vertices"]
        vertices, inverse = np.unique(tris.reshape(-1, 3), axis=0, return_inverse=True)
        return vertices.astype(np.float32), inverse.reshape(-1, 3).astype(np.uint32)
    # Fallback: two crossed bars at ±45°.
    half_m, w_m = 0.046, 0.004
    bar = np.array(
        [
            [-half_m, -w_m, -w_m],
            [half_m, -w_m, -w_m],
            [half_m, w_m, -w_m],
            [-half_m, w_m, -w_m],
            [-half_m, -w_m, w_m],
            [half_m, -w_m, w_m],
            [half_m, w_m, w_m],
            [-half_m, w_m, w_m],
        ]
    )
    quads = [(0, 3, 2, 1), (4, 5, 6, 7), (0, 1, 5, 4), (2, 3, 7, 6), (1, 2, 6, 5), (0, 4, 7, 3)]
    faces = np.array([f for a, b, c, d in quads for f in ((a, b, c), (a, c, d))])
    verts, all_faces = [], []
    for k, yaw_rad in enumerate((math.pi / 4.0, -math.pi / 4.0)):
        cos, sin = math.cos(yaw_rad), math.sin(yaw_rad)
        R_world_bar = np.array([[cos, -sin, 0.0], [sin, cos, 0.0], [0.0, 0.0, 1.0]])
        verts.append(bar @ R_world_bar.T)
        all_faces.append(faces + 8 * k)
    return np.concatenate(verts).astype(np.float32), np.concatenate(all_faces).astype(np.uint32)


# --------------------------------------------------------------------------------------------
# Scene nodes.
# --------------------------------------------------------------------------------------------


@dataclass
class _DroneNodes:
    root: str
    body: viser.FrameHandle
    quad: viser.MeshHandle
    label: viser.LabelHandle
    tether: viser.LineSegmentsHandle
    floor_run: viser.LineSegmentsHandle
    arrow: viser.ArrowsHandle
    uncertainty: viser.IcosphereHandle
    mocap: viser.IcosphereHandle
    mocap_error: viser.LineSegmentsHandle
    truth: viser.IcosphereHandle
    trail: viser.LineSegmentsHandle
    base_column: viser.BoxHandle
    base_exit: viser.IcosphereHandle
    base_drawn: Vec3 | None = None
    faded: bool | None = None
    shown: dict[str, bool] = field(default_factory=dict)
    texts: dict[str, str] = field(default_factory=dict)

    def show(self, name: str, visible: bool) -> None:
        """Set a node's visibility, sending only changes (each assignment is a message)."""
        if self.shown.get(name) != visible:
            getattr(self, name).visible = visible
            self.shown[name] = visible

    def text(self, name: str, text: str) -> None:
        """Set a label's text, sending only changes."""
        if self.texts.get(name) != text:
            getattr(self, name).text = text
            self.texts[name] = text


def _label_text(drone: DroneState, stale: bool, silent_s: float) -> str:
    """Line 1: id and flags; line 2: |T|; line 3: the motion-capture error (when known).

    One value a line keeps the label narrow: it is centred on the drone, and a long line
    ran under the control panel or off the view's edge."""
    est = drone.estimate
    flags = []
    if stale:
        flags.append(f"stale {silent_s:.0f} s")
    if est is not None and est.position_m is None:
        flags.append("position undetermined")
    if drone.last_stop is not None or (est is not None and est.follow.stopped):
        flags.append("STOPPED")
    line1 = drone.id + (f" ({', '.join(flags)})" if flags else "")
    values = []
    if est is not None and not est.on_ground and not stale:
        values.append(f"|T| {tension_norm_n(est):.3f} N")
    mocap = drone.telemetry.position_m if drone.telemetry is not None else None
    if mocap is not None and est is not None and est.position_m is not None and not stale:
        values.append(f"mocap Δ {100.0 * math.dist(est.position_m, mocap):.1f} cm")
    return "\n".join([line1, *values])


class Scene:
    """The server-wide 3D scene of every drone.

    Args:
        server: the viser server.
        settings: the root configuration (floor, bases and tether of each drone until the
            service reports them; ``[service] stale_after_s`` for fading).
    """

    def __init__(self, server: viser.ViserServer, settings: Settings) -> None:
        self._server = server
        self._settings = settings
        self._mesh = load_quadrotor_mesh()
        self._nodes: dict[str, _DroneNodes] = {}
        self._tiers: dict[str, int] = {}
        floor_z_m = settings.base.floor_z_m
        scene = server.scene
        scene.add_grid(
            "/floor",
            width=6.0,
            height=6.0,
            cell_size=0.1,
            section_size=1.0,
            position=(0.0, 0.0, floor_z_m),
        )
        # World axes on the floor below the origin: x red, y green, z blue (viser's frame).
        scene.add_frame(
            "/world_axes",
            axes_length=WORLD_AXES_M,
            axes_radius=0.006,
            position=(0.0, 0.0, floor_z_m),
        )
        for axis, tip in (("x", (1, 0, 0)), ("y", (0, 1, 0)), ("z", (0, 0, 1))):
            scene.add_label(
                f"/world_axes/{axis}_label",
                axis,
                position=(
                    1.1 * WORLD_AXES_M * tip[0],
                    1.1 * WORLD_AXES_M * tip[1],
                    1.1 * WORLD_AXES_M * tip[2],
                ),
                anchor="center-center",
                font_screen_scale=0.8,
            )
        # Until drones appear, frame the configured base.
        position, look_at = camera_framing(
            [settings.base.position_m, (0.0, 0.0, floor_z_m), (1.0, 0.0, 1.0)],
            covered_right=panel_fraction(None),
        )
        server.initial_camera.position = position
        server.initial_camera.look_at = look_at

    @property
    def drawn(self) -> list[str]:
        """Drones with scene nodes."""
        return sorted(self._nodes)

    def remove(self, drone_id: str) -> None:
        """Remove a drone's nodes (a forgotten drone)."""
        nodes = self._nodes.pop(drone_id, None)
        self._tiers.pop(drone_id, None)
        if nodes is not None:
            self._server.scene.remove_by_name(nodes.root)

    def framing_points(self, drones: Sequence[DroneState]) -> list[Sequence[float]]:
        """What a camera must see: bases, drawn bodies, motion-capture markers (the far end
        of the motion-capture error line) of ``drones``, and a floor point."""
        points: list[Sequence[float]] = []
        for drone in drones:
            params = self._settings.for_drone(drone.id)
            points.append(drone.base_m(params.base.position_m))
            body = drone.body_position()
            if body is not None:
                points.append(body)
            if drone.telemetry is not None and drone.telemetry.position_m is not None:
                points.append(drone.telemetry.position_m)
        if not points:
            points.append(self._settings.base.position_m)
        points.append((points[0][0], points[0][1], self._settings.base.floor_z_m))
        return points

    def place_labels(self, drones: Sequence[DroneState]) -> None:
        """Recompute the label tiers of every drawn drone (call when positions moved)."""
        positions = {d.id: p for d in drones if (p := d.body_position()) is not None}
        tiers = label_tiers(positions)
        for drone_id, tier in tiers.items():
            nodes = self._nodes.get(drone_id)
            if nodes is not None and self._tiers.get(drone_id) != tier:
                nodes.label.position = (0.0, 0.0, LABEL_HEIGHT_M + tier * LABEL_STEP_M)
                self._tiers[drone_id] = tier

    def label_heights_m(self) -> dict[str, float]:
        """Drawn label height above each body, metres (for tests)."""
        return {d: LABEL_HEIGHT_M + t * LABEL_STEP_M for d, t in self._tiers.items()}

    def _make_nodes(self, drone: DroneState) -> _DroneNodes:
        scene = self._server.scene
        root = f"/drones/{drone.id}"
        vertices, faces = self._mesh
        empty = np.zeros((1, 2, 3), dtype=np.float32)
        return _DroneNodes(
            root=root,
            body=scene.add_frame(f"{root}/body", axes_length=0.12, axes_radius=0.004),
            quad=scene.add_mesh_simple(
                f"{root}/body/quad",
                vertices,
                faces,
                color=drone.color,
                scale=QUAD_DRAW_SCALE,
                side="double",
            ),
            label=scene.add_label(
                f"{root}/body/label",
                drone.id,
                position=(0.0, 0.0, LABEL_HEIGHT_M),
                anchor="bottom-center",
            ),
            tether=scene.add_line_segments(f"{root}/tether", empty, _TETHER_RGB, thickness=0.006),
            floor_run=scene.add_line_segments(
                f"{root}/floor_run", empty, _FLOOR_RUN_RGB, thickness=0.008, visible=False
            ),
            arrow=scene.add_arrows(
                f"{root}/tension",
                np.array([[[0, 0, 0], [0, 0, 0.01]]], dtype=np.float32),
                _TENSION_RGB,
                shaft_radius=0.006,
                head_radius=0.016,
                head_length=0.04,
            ),
            uncertainty=scene.add_icosphere(
                f"{root}/uncertainty",
                radius=1.0,
                color=drone.color,
                opacity=0.15,
                subdivisions=2,
                cast_shadow=False,
                receive_shadow=False,
                visible=False,
            ),
            mocap=scene.add_icosphere(
                f"{root}/mocap", radius=0.015, color=_MOCAP_RGB, visible=False
            ),
            mocap_error=scene.add_line_segments(
                f"{root}/mocap_error", empty, _MOCAP_RGB, thickness=0.004, visible=False
            ),
            truth=scene.add_icosphere(
                f"{root}/truth", radius=0.012, color=_TRUTH_RGB, visible=False
            ),
            trail=scene.add_line_segments(
                f"{root}/trail", empty, drone.color, thickness=0.003, visible=False
            ),
            base_column=scene.add_box(
                f"{root}/base_column", color=_BASE_RGB, dimensions=(0.08, 0.08, 0.01)
            ),
            base_exit=scene.add_icosphere(f"{root}/base_exit", radius=0.02, color=_BASE_RGB),
        )

    def _fade(self, nodes: _DroneNodes, drone: DroneState, faded: bool) -> None:
        if nodes.faded == faded:
            return
        nodes.quad.opacity = FADED_OPACITY if faded else None
        nodes.quad.color = _STALE_RGB if faded else drone.color
        nodes.faded = faded

    def draw(self, drone: DroneState, now_s: float) -> None:
        """Push one drone's nodes (created on first use)."""
        nodes = self._nodes.get(drone.id)
        if nodes is None:
            nodes = self._nodes[drone.id] = self._make_nodes(drone)
        params = self._settings.for_drone(drone.id)
        floor_z_m = params.base.floor_z_m
        base = drone.base_m(params.base.position_m)
        if nodes.base_drawn != base:
            height_m = max(0.01, base[2] - floor_z_m)
            nodes.base_column.dimensions = (0.05, 0.05, height_m)
            nodes.base_column.position = (base[0], base[1], floor_z_m + height_m / 2.0)
            nodes.base_exit.position = base
            nodes.base_drawn = base

        stale = drone.is_stale(now_s, self._settings.service.stale_after_s)
        self._fade(nodes, drone, stale)
        est = drone.estimate
        body = drone.body_position()
        nodes.show("body", body is not None)
        if body is not None:
            nodes.body.position = body
            if drone.quat_wxyz is not None:
                nodes.body.wxyz = drone.quat_wxyz
            nodes.text("label", _label_text(drone, stale, drone.silent_s(now_s)))
            pts = tether_points(base, body, drone.length_m(params.tether.length_m), floor_z_m)
            on_floor = np.abs(pts[:, 2] - floor_z_m) < 1e-3
            segments = polyline_segments(pts)
            nodes.tether.points = segments
            if nodes.shown.get("tether_stale") != stale:
                nodes.tether.colors = np.array(_STALE_RGB if stale else _TETHER_RGB, dtype=np.uint8)
                nodes.shown["tether_stale"] = stale
            nodes.show("tether", True)
            if on_floor.sum() >= 2 and not stale:
                nodes.floor_run.points = polyline_segments(pts[on_floor])
                nodes.show("floor_run", True)
            else:
                nodes.show("floor_run", False)
        else:
            nodes.show("tether", False)
            nodes.show("floor_run", False)

        show_arrow = est is not None and body is not None and not est.on_ground and not stale
        nodes.show("arrow", show_arrow)
        if show_arrow and est is not None and body is not None:
            nodes.arrow.points = tension_arrow(body, est.tension_n)

        std = est.position_std_m if est is not None else None
        if std is not None and est is not None and est.position_m is not None and not stale:
            nodes.uncertainty.position = est.position_m
            sx, sy, sz = (float(np.clip(2.0 * s, 0.005, 3.0)) for s in std)
            nodes.uncertainty.scale = (sx, sy, sz)
            nodes.show("uncertainty", True)
        else:
            nodes.show("uncertainty", False)

        mocap = drone.telemetry.position_m if drone.telemetry is not None else None
        nodes.show("mocap", mocap is not None and not stale)
        if mocap is not None:
            nodes.mocap.position = mocap
        position = est.position_m if est is not None else None
        has_error = mocap is not None and position is not None and not stale
        nodes.show("mocap_error", has_error)
        if has_error and mocap is not None and position is not None:
            nodes.mocap_error.points = np.array([[position, mocap]], dtype=np.float32)

        nodes.show("truth", drone.truth is not None and not stale)
        if drone.truth is not None:
            nodes.truth.position = drone.truth.position_m

        if len(drone.trail) >= 2 and not stale:
            nodes.trail.points = polyline_segments(np.asarray(drone.trail))
            nodes.show("trail", True)
        else:
            nodes.show("trail", False)
