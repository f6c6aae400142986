"""Frame algebra: property tests (hypothesis) and analytic Jacobians against numerical ones."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from sonarslam.features.geometry import (
    along_line,
    between,
    compose,
    compose_jacobians,
    interpolate_poses,
    inverse,
    line_frame_to_world,
    line_side,
    line_world_to_frame,
    normalize_line,
    segment_on_line,
    transform_points,
    wrap_angle,
)

coord = st.floats(-200.0, 200.0, allow_nan=False)
angle = st.floats(-10.0, 10.0, allow_nan=False)
pose = st.tuples(coord, coord, angle).map(lambda p: np.array(p))
line = st.tuples(st.floats(0.5, 150.0), st.floats(-np.pi, np.pi - 1e-9)).map(lambda p: np.array(p))


def numerical_jacobian(f, x, eps=1e-6):
    x = np.asarray(x, dtype=float)
    y0 = f(x)
    J = np.zeros((y0.size, x.size))
    for i in range(x.size):
        d = np.zeros_like(x)
        d[i] = eps
        diff = f(x + d) - f(x - d)
        diff[1] = wrap_angle(diff[1])  # theta is an angle
        J[:, i] = diff / (2 * eps)
    return J


def same_pose(a, b, tol=1e-9):
    return np.allclose(a[:2], b[:2], atol=tol) and abs(wrap_angle(a[2] - b[2])) < tol


@given(angle)
def test_wrap_angle_range_and_identity(a):
    w = float(wrap_angle(a))
    assert -np.pi <= w < np.pi
    assert abs(np.sin(w) - np.sin(a)) < 1e-9 and abs(np.cos(w) - np.cos(a)) < 1e-9


@given(st.floats(-100, 100), angle)
def test_normalize_line_is_the_same_set_of_points(rho, theta):
    r, t = normalize_line(rho, theta)
    assert r >= 0 and -np.pi <= t < np.pi
    # a point of the original line lies on the normalised one
    p = rho * np.array([np.cos(theta), np.sin(theta)]) + 7.0 * np.array(
        [-np.sin(theta), np.cos(theta)]
    )
    assert abs(p @ np.array([np.cos(t), np.sin(t)]) - r) < 1e-9


@given(pose, pose, pose)
def test_compose_is_associative_and_inverse_cancels(a, b, c):
    assert same_pose(compose(compose(a, b), c), compose(a, compose(b, c)), 1e-7)
    assert same_pose(compose(a, inverse(a)), np.zeros(3), 1e-9)
    assert same_pose(compose(a, between(a, b)), b, 1e-7)


@given(pose, st.lists(st.tuples(coord, coord), min_size=1, max_size=5))
def test_transform_points_matches_compose(a, pts):
    pts = np.array(pts)
    out = transform_points(a, pts)
    via = compose(a, np.column_stack([pts, np.zeros(len(pts))]))[:, :2]
    assert np.allclose(out, via, atol=1e-9)


@given(line, pose)
def test_line_world_to_frame_round_trip_and_points(lw, wTr):
    lr, _, _ = line_world_to_frame(lw, wTr)
    back, _, _ = line_frame_to_world(lr, wTr)
    assert abs(back[0] - lw[0]) < 1e-7 and abs(wrap_angle(back[1] - lw[1])) < 1e-9
    # a world point on the line, moved into frame r, lies on the frame line
    p_w = lw[0] * np.array([np.cos(lw[1]), np.sin(lw[1])]) + 3.0 * np.array(
        [-np.sin(lw[1]), np.cos(lw[1])]
    )
    p_r = transform_points(inverse(wTr), p_w[None])[0]
    assert abs(p_r @ np.array([np.cos(lr[1]), np.sin(lr[1])]) - lr[0]) < 1e-7


@settings(max_examples=200)
@given(line, pose)
def test_line_jacobians_match_numerical(lw, wTr):
    lr, H_line, H_pose = line_world_to_frame(lw, wTr)
    if lr[0] < 1e-3:  # normalisation flips the sign at rho = 0: not differentiable there
        return
    J_line = numerical_jacobian(lambda v: line_world_to_frame(v, wTr)[0], lw)
    J_pose = numerical_jacobian(lambda v: line_world_to_frame(lw, v)[0], wTr)
    assert np.allclose(H_line, J_line, atol=1e-5)
    assert np.allclose(H_pose, J_pose, atol=1e-5)
    lw2, G_line, G_pose = line_frame_to_world(lr, wTr)
    J_line = numerical_jacobian(lambda v: line_frame_to_world(v, wTr)[0], lr)
    J_pose = numerical_jacobian(lambda v: line_frame_to_world(lr, v)[0], wTr)
    assert np.allclose(G_line, J_line, atol=1e-5)
    assert np.allclose(G_pose, J_pose, atol=1e-5)


def test_interpolate_poses_takes_the_short_arc():
    t = np.array([0.0, 1.0])
    poses = np.array([[0.0, 0.0, np.pi - 0.1], [2.0, 4.0, -np.pi + 0.1]])
    mid = interpolate_poses([0.5], t, poses)[0]
    assert np.allclose(mid[:2], [1.0, 2.0], atol=1e-12)
    assert abs(wrap_angle(mid[2] - np.pi)) < 1e-12


@given(pose, pose)
def test_compose_jacobians_match_numerical(a, b):
    J_a, J_b = compose_jacobians(a, b)
    eps = 1e-6
    for i in range(3):
        d = np.zeros(3)
        d[i] = eps
        num_a = compose(a + d, b) - compose(a - d, b)
        num_b = compose(a, b + d) - compose(a, b - d)
        num_a[2], num_b[2] = wrap_angle(num_a[2]), wrap_angle(num_b[2])
        assert np.allclose(J_a[:, i], num_a / (2 * eps), atol=1e-5)
        assert np.allclose(J_b[:, i], num_b / (2 * eps), atol=1e-5)


@given(line, st.floats(-50, 50), st.floats(0.1, 50))
def test_segment_on_line_and_along_line_are_inverse(lw, s0, length):
    ends = segment_on_line(lw, s0, s0 + length)
    # the ends lie on the line, at the asked coordinates along it
    n = np.array([np.cos(lw[1]), np.sin(lw[1])])
    assert np.allclose(ends @ n, lw[0], atol=1e-9)
    assert np.allclose(along_line(lw, ends), [s0, s0 + length], atol=1e-9)


def test_line_side_is_the_one_side_rule():
    """+1 on the side of the line's origin (rho > 0), -1 beyond it; broadcast over lines."""
    line = np.array([5.0, 0.3])
    n = np.array([np.cos(0.3), np.sin(0.3)])
    assert line_side(line, np.zeros(2)) == 1.0
    assert line_side(line, 7.0 * n) == -1.0
    # the same line written (-rho, theta + pi) swaps the signs: +1 is where rho - n.p >= 0
    flipped = np.array([-5.0, 0.3 + np.pi])
    pts = np.array([[0.0, 0.0], 7.0 * n, 3.0 * n + [1.0, -2.0]])
    assert np.all(
        line_side(np.tile(line, (3, 1)), pts) == -line_side(np.tile(flipped, (3, 1)), pts)
    )
