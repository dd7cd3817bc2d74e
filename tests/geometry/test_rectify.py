"""Rectification of a pair of any lens models: rows agree, OpenCV's rotations, Q, E and F."""

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from aicalib_tf.geometry.lens import Lens
from aicalib_tf.geometry.rectify import (compose, essential_matrix, fundamental_matrix, invert, rectified_points,
                                         rectify_pair, relative_pose, rotation_angle_deg)

SIZE = (800, 600)
PIN = Lens("plumb_bob", [[600, 0, 402], [0, 601, 297], [0, 0, 1]], [-0.1, 0.01, 1e-4, -2e-4, 0], SIZE)
FISH = Lens("equidistant", [[280, 0, 398], [0, 280, 301], [0, 0, 1]], [0.02, -0.005, 0.001, -0.0003], SIZE)
IDEAL = Lens("plumb_bob", [[600, 0, 399.5], [0, 600, 299.5], [0, 0, 1]], None, SIZE)


def _rig(vertical=False):
    R = Rotation.from_euler("yxz", [-4.0, 0.7, -0.5], degrees=True).as_matrix()
    c = np.array([0.01, 0.2, 0.003]) if vertical else np.array([0.2, 0.004, -0.01])
    return R, -R @ c


def _points(n=200, seed=0):
    rng = np.random.default_rng(seed)
    return np.column_stack([rng.uniform(-0.6, 0.8, n), rng.uniform(-0.5, 0.6, n), rng.uniform(1.0, 3.0, n)])


@pytest.mark.parametrize("lenses", [(PIN, PIN), (PIN, FISH), (FISH, FISH)], ids=["pinhole", "mixed", "fisheye"])
@pytest.mark.parametrize("vertical", [False, True], ids=["horizontal", "vertical"])
def test_rectified_rows_agree(lenses, vertical):
    R, T = _rig(vertical)
    rect = rectify_pair(*lenses, R, T)
    X1 = _points()
    p1 = rectified_points(lenses[0], rect.R1, rect.P1, lenses[0].project(X1))
    p2 = rectified_points(lenses[1], rect.R2, rect.P2, lenses[1].project(X1 @ R.T + T))
    ok = np.isfinite(p1).all(1) & np.isfinite(p2).all(1)
    assert ok.sum() > 150
    axis = 0 if vertical else 1
    assert rect.vertical == vertical
    np.testing.assert_allclose(p1[ok, axis], p2[ok, axis], atol=1e-6)
    # disparity along the other axis is positive for points in front: Q recovers the point
    d = p1[ok, 1 - axis] - p2[ok, 1 - axis]
    h = np.column_stack([p1[ok], d, np.ones(ok.sum())]) @ rect.Q.T if not vertical else None
    if h is not None:
        Xr = h[:, :3] / h[:, 3:]
        np.testing.assert_allclose(Xr, X1[ok] @ rect.R1.T, rtol=1e-6, atol=1e-6)


def test_rotations_match_opencv_stereo_rectify():
    R, T = _rig()
    K = np.asarray(IDEAL.K)
    R1, R2, *_ = cv2.stereoRectify(K, np.zeros(5), K, np.zeros(5), SIZE, R, T.reshape(3, 1), alpha=-1)
    rect = rectify_pair(IDEAL, IDEAL, R, T)
    np.testing.assert_allclose(rect.R1, R1, atol=1e-9)
    np.testing.assert_allclose(rect.R2, R2, atol=1e-9)
    assert rect.P2[0, 3] == pytest.approx(rect.focal * (rect.R2 @ T)[0])


def test_zero_baseline_is_an_error():
    with pytest.raises(ValueError, match="no baseline"):
        rectify_pair(PIN, PIN, np.eye(3), np.zeros(3))


def test_essential_and_fundamental_matrices():
    R, T = _rig()
    X1 = _points(50)
    X2 = X1 @ R.T + T
    E = essential_matrix(R, T)
    x1, x2 = X1 / X1[:, 2:], X2 / X2[:, 2:]
    assert np.max(np.abs(np.einsum("ni,ij,nj->n", x2, E, x1))) < 1e-12
    K = np.asarray(IDEAL.K)
    F = fundamental_matrix(K, K, R, T)
    u1, u2 = x1 @ K.T, x2 @ K.T
    assert np.max(np.abs(np.einsum("ni,ij,nj->n", u2, F, u1))) < 1e-9
    cvF, _ = cv2.findFundamentalMat(u1[:, :2], u2[:, :2], cv2.FM_8POINT)
    np.testing.assert_allclose(F / np.linalg.norm(F), cvF / np.linalg.norm(cvF) * np.sign(cvF[2, 2] * F[2, 2]), atol=1e-5)


def test_pose_helpers():
    R, T = _rig()
    Ri, Ti = invert(R, T)
    Rc, Tc = compose(R, T, Ri, Ti)
    np.testing.assert_allclose(Rc, np.eye(3), atol=1e-12)
    np.testing.assert_allclose(Tc, 0, atol=1e-12)
    assert rotation_angle_deg(R) == pytest.approx(np.degrees(np.linalg.norm(Rotation.from_matrix(R).as_rotvec())))
    # a board seen by both cameras gives back the rig's pose
    Rb = Rotation.from_euler("xyz", [10, -20, 5], degrees=True).as_matrix()
    tb = np.array([0.1, -0.05, 1.2])
    R2b, t2b = compose(R, T, Rb, tb)
    Rr, Tr = relative_pose(cv2.Rodrigues(Rb)[0], tb, cv2.Rodrigues(R2b)[0], t2b)
    np.testing.assert_allclose(Rr, R, atol=1e-12)
    np.testing.assert_allclose(Tr, T, atol=1e-12)
