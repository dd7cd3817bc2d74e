"""A rendered stereo pair filming a ChArUco board, shared by the video and rig-video tests."""

import pytest

from .boards import CHARUCO


@pytest.fixture(scope="session")
def charuco_pair(tmp_path_factory):
    """A 5 s, 10 fps, 640x480 stereo pair (120 mm baseline) of a hand-held ChArUco board of 5x4 inner corners."""
    from data_gen.video import main as render

    out = tmp_path_factory.mktemp("charuco_pair")
    assert render(["--out", str(out), "--seconds", "5", "--fps", "10", "--size", "640x480", "--pace", "3", "--seed", "3",
                   "--shutter", "0.004", "--rig-baseline", "120", "--board", CHARUCO, "--quiet"]) == 0
    return out
