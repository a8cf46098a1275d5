"""The one set of rotation helpers agrees with MuJoCo's own on random rotations."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from phyagentos.geometry import (
    look_at_quat,
    matrix_to_quat,
    pose_matrix,
    quat_multiply,
    quat_to_matrix,
    rotation_about,
    yaw_quat,
)

RNG = np.random.default_rng(7)
QUATS = [q / np.linalg.norm(q) for q in RNG.normal(size=(200, 4))] + [
    np.array([0.0, 1.0, 0.0, 0.0]), np.array([0.0, 0.0, 1.0, 0.0]), np.array([0.0, 0.0, 0.0, 1.0])]


def test_quaternion_to_matrix_and_back_match_mujoco_on_random_rotations():
    for q in QUATS:
        R = np.empty(9)
        mujoco.mju_quat2Mat(R, q)
        assert np.allclose(quat_to_matrix(q), R.reshape(3, 3), atol=1e-12)
        expected = np.empty(4)
        mujoco.mju_mat2Quat(expected, R)
        assert np.allclose(matrix_to_quat(R), expected, atol=1e-12)  # same branch, same sign


def test_the_product_matches_mujoco():
    for a, b in zip(QUATS[:100], QUATS[100:200]):
        out = np.empty(4)
        mujoco.mju_mulQuat(out, a, b)
        assert np.allclose(quat_multiply(a, b), out, atol=1e-12)


def test_yaw_axis_angle_and_pose_agree():
    assert np.allclose(quat_to_matrix(yaw_quat(0.3)), rotation_about([0, 0, 2.0], 0.3))
    T = pose_matrix([1.0, 2.0, 3.0], yaw_quat(math.pi / 2))
    assert np.allclose(T @ [1.0, 0.0, 0.0, 1.0], [1.0, 3.0, 3.0, 1.0])
    assert np.allclose(pose_matrix([1.0, 2.0, 3.0], T[:3, :3].reshape(-1)), T)


def test_a_camera_looking_down_the_x_axis_sees_along_its_minus_z():
    R = quat_to_matrix(look_at_quat([0.0, 0.0, 1.0], [2.0, 0.0, 1.0]))
    assert np.allclose(R[:, 2], [-1.0, 0.0, 0.0]) and np.allclose(R[:, 1], [0.0, 0.0, 1.0])


@pytest.mark.parametrize(("call", "message"), [
    (lambda: quat_to_matrix([0, 0, 0, 0]), "not all zero"),
    (lambda: quat_to_matrix([1, 0, 0]), "4 finite entries"),
    (lambda: look_at_quat([0, 0, 1], [0, 0, 1]), "equals target"),
    (lambda: look_at_quat([0, 0, 1], [0, 0, 0]), "parallel to up"),
    (lambda: pose_matrix([0, 0, 0], [1, 0]), "quaternion \\(4,\\) or a matrix"),
])
def test_bad_input_is_refused_with_what_was_wrong(call, message):
    with pytest.raises(ValueError, match=message):
        call()
