"""The mandrel's pose in the machine (docs/architecture.md §2).

``pose_at(centerline, travel, eccentricity, lead)`` puts the centerline point at arc length
``travel - lead`` at machine ``(ex, ey, lead)``, its tangent along ``-z`` and its normal along ``+x``.
"""

from __future__ import annotations

import numpy as np
import pytest

from preform.geometry import centerline_from_points, pose_at, shapes


def _rotation(axis, angle):
    """Rodrigues: (3, 3) rotation by angle (rad) about a unit axis."""
    k = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K


@pytest.fixture(scope="module")
def tilted():
    """A straight 1 m centerline from (0.1, 0.2, 0.3) along (1, 2, 2)/3, roll reference +z."""
    start = np.array([0.1, 0.2, 0.3])
    direction = np.array([1.0, 2.0, 2.0]) / 3.0
    return centerline_from_points([start, start + direction], roll_reference=[0.0, 0.0, 1.0])


@pytest.fixture(scope="module")
def bent():
    return centerline_from_points(shapes.bent_tube_path(), roll_reference=[1.0, 0.0, 0.0])


def _is_rotation(R):
    assert np.allclose(R @ R.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(R) == pytest.approx(1.0, abs=1e-12)


def test_straight_mandrel_lead_zero(tilted):
    travel = 0.3
    pose = pose_at(tilted, travel)
    _is_rotation(pose.R)
    T, N = tilted.tangents[0], tilted.normals[0]
    assert np.allclose(pose.to_machine(tilted.points[0]), [0.0, 0.0, travel], atol=1e-15)   # the tip
    assert np.allclose(pose.R @ T, [0.0, 0.0, -1.0], atol=1e-15)
    assert np.allclose(pose.R @ N, [1.0, 0.0, 0.0], atol=1e-15)
    assert np.allclose(pose.R @ tilted.binormals[0], [0.0, -1.0, 0.0], atol=1e-15)
    # every centerline point is on the machine axis, at z = travel - s
    s = np.linspace(0.0, 1.0, 11)
    X = pose.to_machine(tilted.frames_at(s)[0])
    assert np.allclose(X, np.column_stack([0 * s, 0 * s, travel - s]), atol=1e-15)


def test_eccentricity_shifts_x_and_y(bent):
    rng = np.random.default_rng(0)
    x = rng.normal(scale=0.3, size=(50, 3))
    for travel in (0.1, 0.6, 1.2):
        centred = pose_at(bent, travel).to_machine(x)
        shifted = pose_at(bent, travel, eccentricity=(0.02, -0.015)).to_machine(x)
        assert np.allclose(shifted - centred, [0.02, -0.015, 0.0], rtol=0, atol=1e-15)


@pytest.mark.parametrize("travel, lead", [(0.2, 0.05), (0.6, 0.1), (1.0, 0.3), (0.05, 0.2)])
def test_lead_puts_the_centerline_on_the_axis_ahead(bent, travel, lead):
    ecc = (0.01, 0.02)
    pose = pose_at(bent, travel, eccentricity=ecc, lead=lead)
    _is_rotation(pose.R)
    p, T, N, _ = bent.frame_at(travel - lead)            # travel < lead: extrapolated before the tip
    assert np.allclose(pose.to_machine(p), [ecc[0], ecc[1], lead], atol=1e-15)
    assert np.allclose(pose.R @ T, [0.0, 0.0, -1.0], atol=1e-12)
    assert np.allclose(pose.R @ N, [1.0, 0.0, 0.0], atol=1e-12)


def test_lead_on_a_straight_mandrel_is_the_same_pose(tilted):
    """On a straight centerline the lead only moves the reference point along the axis."""
    a, b = pose_at(tilted, 0.4), pose_at(tilted, 0.4, lead=0.15)
    assert np.allclose(a.R, b.R, atol=1e-15) and np.allclose(a.t, b.t, atol=1e-15)


def test_to_machine_and_to_mandrel_are_inverse(bent):
    rng = np.random.default_rng(1)
    x = rng.normal(scale=0.5, size=(100, 3))
    pose = pose_at(bent, 0.7, eccentricity=(0.03, 0.0), lead=0.08)
    assert np.allclose(pose.to_mandrel(pose.to_machine(x)), x, atol=1e-15)
    assert np.allclose(pose.to_machine(pose.to_mandrel(x)), x, atol=1e-15)
    assert np.allclose(pose.to_machine(x[0]), pose.to_machine(x)[0], atol=0)     # (3,) like (n, 3)
    # distances are kept
    d = np.linalg.norm(x[1:] - x[:-1], axis=1)
    X = pose.to_machine(x)
    assert np.allclose(np.linalg.norm(X[1:] - X[:-1], axis=1), d, rtol=1e-14)


@pytest.mark.parametrize("travel, ecc, lead", [(0.0, (0.0, 0.0), 0.0), (0.55, (0.02, -0.01), 0.05),
                                               (1.1, (0.0, 0.03), 0.2), (1.6, (0.01, 0.0), 0.0)])
def test_frame_invariance(travel, ecc, lead):
    """Moving the STL, its centerline and the roll reference by one rigid motion changes nothing in
    the machine frame."""
    vertices, _ = shapes.bent_tube(n_around=16, spacing=0.1)
    path = shapes.bent_tube_path()
    roll = np.array([0.0, 1.0, 0.0])
    Q = _rotation([0.3, -0.5, 0.8], 2.1)
    d = np.array([0.4, -1.3, 2.2])
    moved = centerline_from_points(path @ Q.T + d, roll_reference=Q @ roll)
    original = centerline_from_points(path, roll_reference=roll)
    X = pose_at(original, travel, ecc, lead).to_machine(vertices)
    X_moved = pose_at(moved, travel, ecc, lead).to_machine(vertices @ Q.T + d)
    assert np.allclose(X_moved, X, rtol=0, atol=1e-9)
