"""Draw the 3D scene a recording holds for Foxglove, with matplotlib (docs/figures/).

Writes docs/figures/foxglove_scene.png by default:

    .venv/bin/python scripts/foxglove_picture.py OUT.mcap [--at S] [--out PNG]

OUT.mcap is the output of ``groundstation replay --offline``. The picture is made from the
file's ``scene`` channel, decoded with the schema written in the file (``mcap`` and
``mcap-protobuf-support``), at ``--at`` seconds after its first scene (default: the middle):
every line, arrow, sphere and box of that ``foxglove.SceneUpdate`` (and the entities still
standing from earlier updates), drawn as Foxglove's 3D panel would place them. It is not a
screenshot of Foxglove (no Foxglove app runs on these machines): it shows what the file
tells Foxglove to draw.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory

REPO = Path(__file__).resolve().parents[1]


def _rotate(q: Any, v: np.ndarray) -> np.ndarray:
    w, x, y, z = q.w, q.x, q.y, q.z
    n = math.sqrt(w * w + x * x + y * y + z * z) or 1.0
    w, x, y, z = w / n, x / n, y / n, z / n
    r = np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )
    return v @ r.T


def _rgba(c: Any) -> tuple[float, float, float, float]:
    return (c.r, c.g, c.b, c.a)


def _xyz(p: Any) -> np.ndarray:
    return np.array([p.x, p.y, p.z])


def scene_at(path: Path, at_s: float | None) -> tuple[dict[str, Any], float]:
    """The entities standing at ``at_s`` after the first scene (deletions applied)."""
    updates = []
    with path.open("rb") as fh:
        reader = make_reader(fh, decoder_factories=[DecoderFactory()])
        for _s, _c, message, decoded in reader.iter_decoded_messages(topics=["scene"]):
            updates.append((message.log_time, decoded))
    if not updates:
        raise SystemExit(f"{path}: no 'scene' channel (is it the output of replay --offline?)")
    t0 = updates[0][0]
    span_s = (updates[-1][0] - t0) / 1e9
    at = span_s / 2 if at_s is None else min(max(at_s, 0.0), span_s)
    entities: dict[str, Any] = {}
    for t, update in updates:
        if (t - t0) / 1e9 > at:
            break
        for d in update.deletions:
            entities.pop(d.id, None)
        for e in update.entities:
            entities[e.id] = e
    return entities, at


def draw(entities: dict[str, Any], ax: Any) -> None:
    for e in entities.values():
        for line in e.lines:
            pts = np.array([_xyz(p) for p in line.points])
            ax.plot(*pts.T, color=_rgba(line.color), lw=2.5 if "tether" in e.id else 1.2)
        for arrow in e.arrows:
            start = _xyz(arrow.pose.position)
            d = _rotate(arrow.pose.orientation, np.array([1.0, 0.0, 0.0]))
            length = arrow.shaft_length + arrow.head_length
            ax.quiver(*start, *(d * length), color=_rgba(arrow.color), lw=2, arrow_length_ratio=0.2)
        for sphere in e.spheres:
            c = _xyz(sphere.pose.position)
            u, v = np.mgrid[0 : 2 * np.pi : 24j, 0 : np.pi : 12j]
            unit = np.stack([np.cos(u) * np.sin(v), np.sin(u) * np.sin(v), np.cos(v)], axis=-1)
            pts = c + unit * (_xyz(sphere.size) / 2.0)
            rgba = _rgba(sphere.color)
            ax.plot_surface(*np.moveaxis(pts, -1, 0), color=rgba[:3], alpha=max(rgba[3], 0.15))
        for cube in e.cubes:
            half = _xyz(cube.size) / 2.0
            corners = (
                np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
                * half
            )
            pts = _rotate(cube.pose.orientation, corners) + _xyz(cube.pose.position)
            for i in range(8):
                for j in range(i + 1, 8):
                    if bin(i ^ j).count("1") == 1:  # an edge
                        ax.plot(*pts[[i, j]].T, color=_rgba(cube.color), lw=1.5)
        for text in e.texts:
            ax.text(*_xyz(text.pose.position), text.text, fontsize=7, ha="center")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("mcap", type=Path, help="output of groundstation replay --offline")
    parser.add_argument("--at", type=float, help="seconds after the first scene (the middle)")
    parser.add_argument(
        "--out", type=Path, default=REPO / "docs" / "figures" / "foxglove_scene.png"
    )
    args = parser.parse_args()
    entities, at = scene_at(args.mcap, args.at)
    fig = plt.figure(figsize=(7.5, 6.0))
    ax = fig.add_subplot(projection="3d")
    draw(entities, ax)
    xs = np.arange(-0.5, 2.01, 0.5)
    for x in xs:  # the floor grid, as Foxglove's Grid layer of the layout
        ax.plot([x, x], [-1.0, 1.0], [0, 0], color="#c8ced3", lw=0.6)
    for y in np.arange(-1.0, 1.01, 0.5):
        ax.plot([xs[0], xs[-1]], [y, y], [0, 0], color="#c8ced3", lw=0.6)
    ax.set_xlim(-0.5, 2.0)
    ax.set_ylim(-1.0, 1.0)
    ax.set_zlim(0.0, 1.6)
    ax.set_box_aspect((2.5, 2.0, 1.6))
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_zlabel("z (m)")
    ax.view_init(elev=18, azim=-60)
    ax.set_title(
        f"{args.mcap.name}: the 'scene' channel at {at:.1f} s\n"
        "(decoded foxglove.SceneUpdate drawn with matplotlib)",
        fontsize=9,
    )
    args.out.parent.mkdir(parents=True, exist_ok=True)
    tmp = args.out.with_name(f".{args.out.name}.tmp-{os.getpid()}.png")
    fig.savefig(tmp, dpi=110, bbox_inches="tight")
    os.replace(tmp, args.out)
    print(f"wrote {args.out} ({len(entities)} entities)", file=sys.stderr)


if __name__ == "__main__":
    main()
