"""Circle grid detection, the projected-centre bias correction and calibration end to end, on
renders with exact truth (a pinhole and a barrel lens)."""

import functools
import json

import cv2
import numpy as np
import pytest

from aicalib_tf.calib.circle_bias import calibrate_circles, centre_offsets
from aicalib_tf.calib.fit import View, calibrate_camera
from aicalib_tf.detect.boards.circles import detect_circles, make_detector
from aicalib_tf.geometry.circles import parse_board, pose_maps, render_view

SIZE = (640, 480)
K = np.array([[560.0, 0.0, 324.0], [0.0, 560.0, 236.0], [0.0, 0.0, 1.0]])
BARREL = np.array([-0.25, 0.08, 0.0, 0.0, 0.0])
BOARD = parse_board("circles:4x11,spacing=20mm,asymmetric")
BIG = parse_board("circles:4x11,spacing=20mm,asymmetric,diameter=22mm")  # a larger bias


def _poses(board, n, seed=3):
    rng = np.random.default_rng(seed)
    pts = board.object_points()
    mid = (pts.min(axis=0) + pts.max(axis=0)) / 2
    out = []
    while len(out) < n:
        rvec = np.array([*rng.uniform(-0.7, 0.7, 2), rng.uniform(-0.3, 0.3)])
        R, _ = cv2.Rodrigues(rvec)
        z = rng.uniform(320, 460)
        tvec = np.array([rng.uniform(-0.2, 0.2) * z, rng.uniform(-0.15, 0.15) * z, z]) - R @ mid
        uv = cv2.projectPoints(pts, rvec, tvec, K, None)[0].reshape(-1, 2)
        if np.all((uv > 30) & (uv < np.array(SIZE) - 30)):
            out.append((rvec, tvec))
    return out


def _render(board, dist, rvec, tvec, seed=0):
    img = render_view(board, SIZE, *pose_maps(K, dist, rvec, tvec), supersample=3)
    img = img + np.random.default_rng(seed).normal(0, 1 / 255, img.shape)
    return np.round(np.clip(img, 0, 1) * 255).astype(np.uint8)


@pytest.fixture(scope="module")
def barrel_views():
    """(poses, truth, OpenCV's centres, ours) for the barrel lens, views OpenCV finds."""
    rows = []
    for k, (rvec, tvec) in enumerate(_poses(BOARD, 12)):
        img = _render(BOARD, BARREL, rvec, tvec, seed=k)
        cv_hit = detect_circles(img, BOARD, refine="opencv")
        if cv_hit is None:
            continue
        truth = cv2.projectPoints(BOARD.object_points(), rvec, tvec, K, BARREL)[0].reshape(-1, 2)
        rows.append(((rvec, tvec), truth, cv_hit[0], detect_circles(img, BOARD)[0]))
    assert len(rows) >= 8
    return rows


def test_centres_match_truth_after_the_bias_correction(barrel_views):
    raw, fixed = [], []
    for (rvec, tvec), truth, _, ours in barrel_views:
        off = centre_offsets(BOARD.object_points(), BOARD.radius, rvec, tvec, "plumb_bob", K, BARREL)
        raw.append(np.linalg.norm(ours - truth, axis=1))
        fixed.append(np.linalg.norm(ours - off - truth, axis=1))
    raw, fixed = np.concatenate(raw), np.concatenate(fixed)
    assert np.mean(raw) > 0.03  # the bias is there, and larger than the noise
    assert np.mean(fixed) < 0.02 and np.max(fixed) < 0.08


def test_offsets_scale_with_radius_and_vanish_facing_the_camera():
    c = BOARD.object_points()[:5]
    rvec, tvec = np.array([0.5, 0.2, 0.0]), np.array([-50.0, -40.0, 300.0])
    a = centre_offsets(c, 2.0, rvec, tvec, "plumb_bob", K, np.zeros(5))
    b = centre_offsets(c, 4.0, rvec, tvec, "plumb_bob", K, np.zeros(5))
    assert np.allclose(b, 4 * a, rtol=0.02)  # second order in the radius
    flat = centre_offsets(c, 4.0, np.zeros(3), tvec, "plumb_bob", K, np.zeros(5))
    assert np.max(np.abs(flat)) < 1e-9  # a fronto-parallel circle's image is a circle about its centre


@pytest.mark.parametrize("lens", ["pinhole", "barrel"])
def test_calibration_with_correction_beats_opencv(lens):
    dist = BARREL if lens == "barrel" else np.zeros(5)
    views, cv_centres = [], []
    for k, (rvec, tvec) in enumerate(_poses(BIG, 12, seed=7)):
        hit = detect_circles(_render(BIG, dist, rvec, tvec, seed=k), BIG, refine="opencv")
        if hit is not None:
            cv_centres.append(hit[0].astype(np.float32))
            views.append(View(f"v{k}", detect_circles(_render(BIG, dist, rvec, tvec, seed=k), BIG)[0], hit[1]))
    assert len(views) >= 8
    fit = functools.partial(calibrate_camera, pattern_size=BIG.pattern_size, square_size=BIG.square_size,
                            image_size=SIZE, model="plumb_bob", reject_outliers=False, flex="off")
    fx_err, pp_err = {}, {}
    for it in (0, 2):
        cal, _ = calibrate_circles(views, BIG, fit, iterations=it)
        fx_err[it], pp_err[it] = abs(cal.K[0, 0] / K[0, 0] - 1), np.hypot(*(cal.K[:2, 2] - K[:2, 2]))
    obj = [BIG.object_points().astype(np.float32)] * len(views)
    _, Kcv, *_ = cv2.calibrateCamera(obj, cv_centres, SIZE, None, None)
    fx_err["cv"], pp_err["cv"] = abs(Kcv[0, 0] / K[0, 0] - 1), np.hypot(*(Kcv[:2, 2] - K[:2, 2]))
    assert fx_err[2] < 2e-4 and pp_err[2] < 0.2, (fx_err, pp_err)
    assert fx_err[2] + pp_err[2] / 560 < 0.7 * min(fx_err[0] + pp_err[0] / 560, fx_err["cv"] + pp_err["cv"] / 560)


def test_symmetric_grid_detected_in_order():
    board = parse_board("circles:7x6,spacing=20mm,symmetric")
    rvec, tvec = np.array([0.3, -0.2, 0.05]), np.array([-60.0, -50.0, 380.0])
    img = _render(board, np.zeros(5), rvec, tvec)
    hit = make_detector(board)(img)
    truth = cv2.projectPoints(board.object_points(), rvec, tvec, K, None)[0].reshape(-1, 2)
    assert hit is not None and np.max(np.linalg.norm(hit[0] - truth, axis=1)) < 0.2
    assert make_detector(board)(np.full((480, 640), 200, np.uint8)) is None


def test_calibrate_cli_end_to_end(tmp_path):
    from aicalib_tf.calibrate import main

    for k, (rvec, tvec) in enumerate(_poses(BOARD, 8, seed=5)):
        cv2.imwrite(str(tmp_path / f"v{k}.png"), _render(BOARD, np.zeros(5), rvec, tvec, seed=k))
    out = tmp_path / "out"
    rc = main([str(tmp_path / "*.png"), "--board", "circles:4x11,spacing=20mm,asymmetric", "--model", "plumb_bob",
               "--out", str(out), "--quiet"])
    assert rc == 0
    cam = json.loads((out / "camera.json").read_text())
    text = json.dumps(cam)
    assert "circle_bias_iterations" in text
    assert "partial" not in (out / "report.txt").read_text()
    fx = cam["K"][0][0] if "K" in cam else cam["camera_matrix"][0][0]
    assert fx == pytest.approx(560.0, rel=1e-3)


def test_centroid_holds_under_blur_and_a_light_gradient():
    ours, theirs = [], []
    for k, (rvec, tvec) in enumerate(_poses(BOARD, 5, seed=11)):
        img = render_view(BOARD, SIZE, *pose_maps(K, np.zeros(5), rvec, tvec), supersample=3).astype(np.float64)
        img = cv2.GaussianBlur(img, (0, 0), 1.5) * (1 - 0.4 * np.linspace(0, 1, SIZE[0])[None, :])
        img = np.round(np.clip(img + np.random.default_rng(k).normal(0, 1 / 255, img.shape), 0, 1) * 255)
        img = img.astype(np.uint8)
        truth = cv2.projectPoints(BOARD.object_points(), rvec, tvec, K, None)[0].reshape(-1, 2)
        truth = truth + centre_offsets(BOARD.object_points(), BOARD.radius, rvec, tvec, "plumb_bob", K, np.zeros(5))
        cv_hit = detect_circles(img, BOARD, refine="opencv")
        if cv_hit is not None:
            theirs.append(np.linalg.norm(cv_hit[0] - truth, axis=1))
            ours.append(np.linalg.norm(detect_circles(img, BOARD)[0] - truth, axis=1))
    assert len(ours) >= 3
    assert np.mean(np.concatenate(ours)) < 0.6 * np.mean(np.concatenate(theirs)) and np.mean(np.concatenate(ours)) < 0.02
