"""One g and one quaternion → rotation for the estimator (groundstation/attitude.py).

The per-message path turns each Telemetry's attitude into ``R_world_body`` once
(groundstation/estimator/observation.py) and hands the rows to the observation, the contact
stage and the slow stage; calibration and offline work use the batch form. These tests hold
the forms equal to each other and to scipy's rotation, and hold the estimator's modules to
the one definition of each.
"""

from __future__ import annotations

import ast
import math
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from groundstation import attitude
from groundstation.contact import vertical_accel_from_rows_mps2, vertical_accel_mps2
from groundstation.tension import DegenerateQuaternionError, rotation_rows, rotation_world_body

ROOT = Path(__file__).resolve().parent.parent / "groundstation"
SEPARATE = ("sim", "bridges")
"""Kept apart on purpose: the simulator (a simulator that imported the code it checks would
prove nothing) and the drone bridges with their fake drone (the Crazyflie firmware's own
unit conversion, and a stand-in for the drone)."""
CONFIG_OWN_G = "config.py"
"""The configuration keeps its own standard gravity for plausibility hints only: the
simulator imports the configuration, so the configuration imports no estimator module."""


def _quats(n: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    q = rng.normal(size=(n, 4))
    q *= rng.uniform(0.5, 2.0, size=(n, 1))  # unnormalised on purpose
    return q


def test_rows_are_scipys_rotation() -> None:
    for q in _quats(200):
        w, x, y, z = q
        expected = Rotation.from_quat([x, y, z, w]).as_matrix()  # scipy: scalar last
        np.testing.assert_allclose(attitude.rows_from_quat_wxyz(tuple(q)), expected, atol=1e-14)


def test_batch_rows_and_array_forms_agree() -> None:
    q = _quats(300, seed=1)
    batch = attitude.rotations_world_body(q)
    for k in range(len(q)):
        rows = np.array(attitude.rows_from_quat_wxyz(tuple(q[k])))
        np.testing.assert_allclose(batch[k], rows, rtol=0.0, atol=2e-16 * 8)
        np.testing.assert_array_equal(rotation_world_body(q[k]), rows)
        assert rotation_rows(q[k]) == attitude.rows_from_quat_wxyz(tuple(q[k]))


def test_degenerate_quaternions_are_refused_where_messages_enter() -> None:
    for bad in ([0.0, 0.0, 0.0, 0.0], [math.nan, 0.0, 0.0, 1.0], [1.0, 0.0, 0.0]):
        with pytest.raises(DegenerateQuaternionError):
            rotation_rows(bad)


def test_contacts_vertical_acceleration_on_rows_is_the_quaternions() -> None:
    rng = np.random.default_rng(2)
    for q in _quats(100, seed=3):
        f = rng.normal(0.0, 3.0, size=3) + np.array([0.0, 0.0, attitude.GRAVITY_MPS2])
        rows = attitude.rows_from_quat_wxyz(tuple(q))
        assert vertical_accel_from_rows_mps2(tuple(f), rows) == pytest.approx(
            vertical_accel_mps2(tuple(f), tuple(q)), abs=1e-12
        )
        # (R f)_z − g by matrix product
        assert vertical_accel_from_rows_mps2(tuple(f), rows) == pytest.approx(
            float((np.array(rows) @ f)[2]) - attitude.GRAVITY_MPS2, abs=1e-12
        )


def _estimator_modules() -> list[Path]:
    return [
        p
        for p in sorted(ROOT.rglob("*.py"))
        if p.relative_to(ROOT).parts[0] not in SEPARATE and p.name != CONFIG_OWN_G
    ]


def test_one_g() -> None:
    """No module but attitude.py writes g: a float literal within 1 % of 9.81 in code
    (docstrings aside) is a second definition."""
    found = []
    for path in _estimator_modules():
        if path.name == "attitude.py":
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            if (
                isinstance(node, ast.Constant)
                and isinstance(node.value, float)
                and abs(node.value - 9.81) < 0.1
            ):
                found.append(f"{path.relative_to(ROOT)}:{node.lineno}")
    assert found == [], f"g written outside groundstation/attitude.py: {found}"
    assert ROOT.joinpath("attitude.py").read_text().count("GRAVITY_MPS2 = ") == 1


def test_one_quaternion_to_rotation() -> None:
    """The rotation's products of quaternion components (``x·y − w·z``, the (0, 1) entry)
    appear in attitude.py alone."""
    found = []
    for path in _estimator_modules():
        if path.name == "attitude.py":
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.BinOp) and isinstance(node.op, ast.Sub):
                text = ast.unparse(node).replace(" ", "")
                if text in ("x*y-w*z", "xy-wz"):
                    found.append(f"{path.relative_to(ROOT)}:{node.lineno}")
    assert found == [], f"a quaternion turned into a rotation outside attitude.py: {found}"
