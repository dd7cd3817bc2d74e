import importlib.util
from pathlib import Path

import pytest

pytest.importorskip("keras")

_spec = importlib.util.spec_from_file_location(
    "inference_precision", Path(__file__).parents[2] / "benchmarks" / "inference_precision.py")
ip = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(ip)


def test_both_precisions_score_the_shipped_model_alike(capsys):
    assert ip.main(["--images", "3", "--repeats", "1"]) == 0
    rows = {line.split("|")[1].strip(): [float(v) for v in line.split("|")[2:7]]
            for line in capsys.readouterr().out.splitlines() if line.startswith("| float32") or line.startswith("| bfloat16")}
    assert set(rows) == {"float32", "bfloat16"}
    f32, bf16 = rows["float32"], rows["bfloat16"]
    assert f32[1] > 0.5 and f32[2] < 0.5  # recall, localisation median px: a working model
    assert abs(f32[0] - bf16[0]) < 0.05 and abs(f32[1] - bf16[1]) < 0.05


@pytest.mark.parametrize("args", [["--images", "0"], ["--repeats", "0"]])
def test_counts_below_one_exit_2_with_a_clear_message(capsys, args):
    with pytest.raises(SystemExit) as exc:
        ip.main(args)
    assert exc.value.code == 2 and "--images and --repeats must be >= 1" in capsys.readouterr().err
