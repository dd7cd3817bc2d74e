"""The rig command line: pairing rules, bad input, and an end-to-end run on rendered rig photos."""

import json

import cv2
import numpy as np
import pytest

from aicalib_tf.calibrate import main
from aicalib_tf.calib.rig.workflow import pair_images, parse_rig
from aicalib_tf.geometry.rectify import rotation_angle_deg


def test_parse_rig_items():
    assert parse_rig(["cam0=left/*.png", "right=r/*.jpg"]) == [("cam0", "left/*.png"), ("right", "r/*.jpg")]
    for bad in (["cam0=a"], ["cam0", "cam1=b"], ["cam0=a", "cam0=b"], ["0cam=a", "cam1=b"], ["cam0=", "cam1=b"]):
        with pytest.raises(ValueError):
            parse_rig(bad)


def test_pairing_by_number_by_stem_and_by_order():
    p = pair_images({"l": ["d/left01.png", "d/left02.png", "d/left03.png"], "r": ["e/right02.png", "e/right01.png"]})
    assert p.rule.startswith("the number") and [n for n, _ in p.frames] == ["01", "02", "03"]
    assert p.frames[0][1] == {"l": "d/left01.png", "r": "e/right01.png"} and p.unpaired == {"l": ["d/left03.png"]}
    p = pair_images({"a": ["x/img_a.png", "x/img_b.png"], "b": ["y/img_a.png", "y/img_b.png"]})
    assert p.rule.startswith("the same file name") and p.frames[1][1] == {"a": "x/img_b.png", "b": "y/img_b.png"}
    p = pair_images({"a": ["x/p.png", "x/q.png"], "b": ["y/s.png", "y/t.png"]})
    assert p.rule.startswith("sorted order") and p.frames[1][1] == {"a": "x/q.png", "b": "y/t.png"}
    with pytest.raises(ValueError, match="cannot pair"):
        pair_images({"a": ["x/p.png", "x/q.png"], "b": ["y/s.png"]})


@pytest.fixture(scope="module")
def rig_photos(tmp_path_factory):
    from data_gen.rig import make_rig_sequence

    root = tmp_path_factory.mktemp("rig")
    truth, frames = make_rig_sequence(3, pairs=9, lenses=("pinhole", "pinhole"), size=(640, 480),
                                      baseline=(80.0, 150.0))
    for side in ("left", "right"):
        (root / side).mkdir()
    for f, (a, b) in enumerate(frames):
        cv2.imwrite(str(root / "left" / f"left{f + 1:02d}.png"), a.image)
        cv2.imwrite(str(root / "right" / f"right{f + 1:02d}.png"), b.image)
    return root, truth


def test_rig_cli_end_to_end(rig_photos, tmp_path, capsys):
    root, truth = rig_photos
    out = tmp_path / "out"
    rc = main(["--rig", f"cam0={root}/left/*.png", f"cam1={root}/right/*.png", "--pattern", "9x6",
               "--square", f"{truth.board.square_size}mm", "--out", str(out), "--quiet"])
    text = capsys.readouterr().out
    assert rc == 0, text
    assert "paired by the number ending each file name" in text and "verdict: cam0-cam1" in text
    for name in ("intrinsics.yml", "extrinsics.yml", "cam0_camera_info.yaml", "cam1_camera_info.yaml", "rig.json",
                 "report.png", "report.txt", "cam0/camera.yaml"):
        assert (out / name).is_file(), name
    rig = json.loads((out / "rig.json").read_text())
    T = np.asarray(rig["T"])[1]
    assert abs(np.linalg.norm(T) - truth.baseline()) < 1e-3 * truth.baseline()
    assert rotation_angle_deg(np.asarray(rig["R"])[1] @ truth.R[1].T) < 0.05
    pair = rig["quality"]["pairs"][0]
    assert pair["held_out_rms_px"] < 0.1 and rig["board"]["square_unit"] == "mm"


def test_rig_cli_reports_a_pair_of_another_size(rig_photos, tmp_path, capsys):
    root, truth = rig_photos
    odd = tmp_path / "right"
    odd.mkdir()
    for f in sorted((root / "right").glob("*.png")):
        img = cv2.imread(str(f), cv2.IMREAD_GRAYSCALE)
        cv2.imwrite(str(odd / f.name), cv2.resize(img, (320, 240)) if f.name == "right04.png" else img)
    rc = main(["--rig", f"cam0={root}/left/*.png", f"cam1={odd}/*.png", "--pattern", "9x6", "--out",
               str(tmp_path / "o"), "--quiet"])
    text = capsys.readouterr().out
    assert rc == 0
    assert "pair 04: cam1's right04.png is 320x240 but cam1's other images are 640x480" in text


def test_rig_cli_bad_input(rig_photos, tmp_path, capsys):
    root, _ = rig_photos
    assert main(["--rig", f"cam0={root}/left/*.png", f"cam1={tmp_path}/none/*.png", "--pattern", "9x6",
                 "--out", str(tmp_path / "o")]) == 2
    assert "cam1: no images match" in capsys.readouterr().err
    assert main(["--rig", f"cam0={root}/left/*.png", "--pattern", "9x6"]) == 2
    assert "at least two cameras" in capsys.readouterr().err
    assert main(["--rig", f"cam0={root}/left/*.png", f"cam1={root}/right/*.png", str(root), "--pattern", "9x6"]) == 2
    assert main(["--rig", f"cam0={root}/left/*.png", f"cam1={root}/right/*.png", "--pattern", "9x6",
                 "--model", "plumb_bob,equidistant,plumb_bob", "--out", str(tmp_path / "o")]) == 2
    assert "3 lens models for 2 cameras" in capsys.readouterr().err
    assert main([f"{root}/left/*.png", "--pattern", "9x6", "--model", "plumb_bob,equidistant"]) == 2
    assert "goes with --rig" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_rig_of_one_camera_with_copies_of_its_images_is_failed_not_good(rig_photos, tmp_path, capsys):
    """The same photos under two names: no baseline. Exit 1, rig.json says failed, no stereo files."""
    import shutil

    root, _ = rig_photos
    shutil.copytree(root / "left", tmp_path / "copy")
    out = tmp_path / "out"
    code = main(["--rig", f"cam0={root / 'left' / '*.png'}", f"cam1={tmp_path / 'copy' / '*.png'}", "--pattern", "9x6",
                 "--square", "25mm", "--model", "plumb_bob", "--out", str(out), "--quiet"])
    text = capsys.readouterr().out
    assert code == 1 and "FAILED" in text and "same images" in text
    verdicts = [line for line in text.splitlines() if line.startswith("verdict:")]
    assert verdicts and all("failed" in v and "good" not in v for v in verdicts), verdicts  # one verdict per run
    rig = json.loads((out / "rig.json").read_text())
    assert rig["quality"]["status"] == "failed" and rig["quality"]["problems"]
    assert rig["quality"]["verdict"].startswith("failed")
    assert (out / "cam0" / "camera.yaml").exists() and not (out / "intrinsics.yml").exists()


def test_rig_given_one_folder_twice_is_refused(rig_photos, tmp_path, capsys):
    root, _ = rig_photos
    pattern = str(root / "left" / "*.png")
    assert main(["--rig", f"cam0={pattern}", f"cam1={pattern}", "--pattern", "9x6", "--out", str(tmp_path / "o")]) == 2
    assert "the same image file" in capsys.readouterr().err and not (tmp_path / "o").exists()


def test_a_charuco_rig_calibrates_from_views_that_each_camera_sees_in_part(tmp_path, capsys):
    from aicalib_tf.geometry.charuco import parse_board
    from data_gen.rig import make_rig_sequence

    spec = "charuco:11x8,square=30mm,marker=22mm,dict=DICT_5X5_100"
    board = parse_board(spec)
    truth, frames = make_rig_sequence(4, pairs=8, lenses=("pinhole", "pinhole"), size=(640, 480),
                                      baseline=(150.0, 300.0), board=board)
    partial = 0
    for side, k in (("left", 0), ("right", 1)):
        (tmp_path / side).mkdir()
        for f, frame in enumerate(frames):
            cv2.imwrite(str(tmp_path / side / f"{side}{f + 1:02d}.png"), frame[k].image)
            partial += not all(frame[k].label["visible"])
    assert partial >= 4  # boards cut by the frame: the markers name the corners each camera sees
    out = tmp_path / "out"
    rc = main(["--rig", f"cam0={tmp_path}/left/*.png", f"cam1={tmp_path}/right/*.png", "--board", spec,
               "--out", str(out), "--quiet"])
    text = capsys.readouterr().out
    assert rc == 0, text
    rig = json.loads((out / "rig.json").read_text())
    assert rig["quality"]["status"] == "ok" and rig["meta"]["board"] == spec, text
    baseline = float(np.linalg.norm(np.asarray(rig["T"])[1]))
    assert abs(baseline / truth.baseline() - 1) < 0.002, (baseline, truth.baseline())
    # within 0.1° or three of the rig's own σ: the model choice may give one camera a richer lens
    # model (rational_polynomial here), whose fit leaves the rotation less determined
    sigma = rig["quality"]["pairs"][0]["rotation_std_deg"]
    assert rotation_angle_deg(np.asarray(rig["R"])[1] @ truth.R[1].T) < max(0.1, 3 * sigma), sigma


def test_a_circular_fisheye_rig_keeps_and_uses_each_cameras_image_circle(tmp_path, capsys):
    from tests.calib.rig.synthetic import check_circular_rig_output, circular_rig

    truth, frames = circular_rig()
    for side, k in (("left", 0), ("right", 1)):
        (tmp_path / side).mkdir()
        for f, frame in enumerate(frames):
            cv2.imwrite(str(tmp_path / side / f"{side}{f + 1:02d}.png"), frame[k].image)
    out = tmp_path / "out"
    rc = main(["--rig", f"cam0={tmp_path}/left/*.png", f"cam1={tmp_path}/right/*.png", "--pattern", "9x6",
               "--square", f"{truth.board.square_size}mm", "--out", str(out), "--quiet"])
    text = capsys.readouterr().out
    assert rc == 0, text
    check_circular_rig_output(out, truth, text)
