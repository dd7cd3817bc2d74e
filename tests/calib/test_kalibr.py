"""calib.kalibr: Kalibr's camchain.yaml for every model it knows, rigs with T_cn_cnm1, and the reader."""

from __future__ import annotations

from types import SimpleNamespace

import cv2
import numpy as np
import pytest

from aicalib_tf.calib import files as F
from aicalib_tf.calib.kalibr import load_camchain, to_camchain_yaml
from tests.calib.test_files import _cal

KALIBR = {"plumb_bob": ("pinhole", "radtan"), "equidistant": ("pinhole", "equidistant"), "ds": ("ds", "none"),
          "eucm": ("eucm", "none")}


@pytest.mark.parametrize("model", sorted(KALIBR))
def test_camchain_of_one_camera_parses_and_holds_the_lens(model, tmp_path):
    cal = _cal(model)
    F.save_calibration(cal, tmp_path)
    text = (tmp_path / "camchain.yaml").read_text()
    cam = load_camchain(text)["cam0"]
    assert (cam["camera_model"], cam["distortion_model"]) == KALIBR[model]
    k = [cal.K[0, 0], cal.K[1, 1], cal.K[0, 2], cal.K[1, 2]]
    d = list(cal.dist)
    if model in ("ds", "eucm"):
        assert cam["intrinsics"] == d + k and cam["distortion_coeffs"] == []
    else:
        assert cam["intrinsics"] == k and cam["distortion_coeffs"] == d[:4]
    assert cam["resolution"] == list(cal.image_size) and cam["rostopic"] == "/cam0/image_raw"
    assert ("k3 = 0.01 is left out" in text) == (model == "plumb_bob")
    try:
        import yaml
    except ImportError:
        return
    assert yaml.safe_load(text)["cam0"] == cam  # pragma: no cover (PyYAML is optional)


def test_models_without_a_kalibr_name_write_no_camera():
    text = to_camchain_yaml(_cal("rational_polynomial"))
    assert "rational_polynomial has no Kalibr camera model" in text and load_camchain(text) == {}


def test_rig_camchain_has_the_transform_between_consecutive_cameras_in_metres():
    cams = [_cal("plumb_bob"), _cal("ds"), _cal("equidistant")]
    R = np.stack([np.eye(3), cv2.Rodrigues(np.array([0.0, 0.1, 0.0]))[0], cv2.Rodrigues(np.array([0.02, -0.1, 0.05]))[0]])
    T = np.array([[0.0, 0.0, 0.0], [-120.0, 1.0, 2.0], [120.0, -3.0, 0.5]])  # mm, X_k = R_k X_0 + T_k
    rig = SimpleNamespace(cameras=[c if c.square_unit else _unit(c, "mm") for c in cams], R=R, T=T)
    chain = load_camchain(to_camchain_yaml(rig))
    assert sorted(chain) == ["cam0", "cam1", "cam2"] and "T_cn_cnm1" not in chain["cam0"]
    X0 = np.array([0.3, -0.2, 1.5])  # metres, in camera 0's frame
    Xs = [R[k] @ X0 + T[k] / 1000.0 for k in range(3)]
    for k in (1, 2):
        M = np.array(chain[f"cam{k}"]["T_cn_cnm1"])
        assert M.shape == (4, 4) and np.allclose(M[3], [0, 0, 0, 1])
        np.testing.assert_allclose(M[:3, :3] @ Xs[k - 1] + M[:3, 3], Xs[k], atol=1e-12)
    assert chain["cam1"]["camera_model"] == "ds" and chain["cam1"]["cam_overlaps"] == [0, 2]


def _unit(cal, unit):
    import dataclasses

    return dataclasses.replace(cal, square_unit=unit)
