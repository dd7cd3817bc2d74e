"""tf.data over data_gen's TFRecord shards: what TensorFlow reads back, the share of each input
pipeline, resuming at an epoch, and clear errors."""

import json

import numpy as np
import pytest

tf = pytest.importorskip("tensorflow")

from aicalib_tf.cnn.tfrecord_data import corner_dataset, find_shards  # noqa: E402
from data_gen import make_sample  # noqa: E402
from data_gen.dataset import DatasetConfig  # noqa: E402
from data_gen.shards import ShardConfig, write_shards  # noqa: E402


@pytest.fixture(scope="module")
def shards(tmp_path_factory):
    out = tmp_path_factory.mktemp("tfrecord") / "shards"
    write_shards(ShardConfig(DatasetConfig(out=out, count=5, preset="train", seed=3, size=(320, 240)), shards=2),
                 progress=False)
    return out


def test_tensorflow_reads_back_the_images_and_corners(shards):
    files = find_shards(str(shards / "*.tfrecord"))
    assert [f.rsplit("/", 1)[1] for f in files] == ["data-00000-of-00002.tfrecord", "data-00001-of-00002.tfrecord"]
    feats = {"image": tf.io.FixedLenFeature([], tf.string), "index": tf.io.FixedLenFeature([1], tf.int64),
             "height": tf.io.FixedLenFeature([1], tf.int64), "corners": tf.io.VarLenFeature(tf.float32),
             "label": tf.io.FixedLenFeature([], tf.string), "mean": tf.io.FixedLenFeature([1], tf.float32)}
    seen = []
    for rec in tf.data.TFRecordDataset(files):  # TensorFlow checks both CRCs of every record
        ex = tf.io.parse_single_example(rec, feats)
        i = int(ex["index"][0])
        s = make_sample("train", 3, i, size=(320, 240))
        img = np.frombuffer(ex["image"].numpy(), np.uint8).reshape(240, 320)
        np.testing.assert_array_equal(img, s.image)
        want = s.corners[s.visible] if s.label["has_board"] else np.zeros((0, 2))
        np.testing.assert_allclose(tf.sparse.to_dense(ex["corners"]).numpy().reshape(-1, 2), want, atol=1e-4)
        assert json.loads(ex["label"].numpy())["seed"] == s.label["seed"]
        assert float(ex["mean"][0]) == pytest.approx(s.image.mean(), rel=1e-6)
        seen.append(i)
    assert seen == [0, 1, 2, 3, 4]


def _batches(files, **kw):
    args = dict(per_replica_batch=4, steps=2, seed=1, first_epoch=0, epochs=2, deterministic=True) | kw
    return list(corner_dataset(files, **args).as_numpy_iterator())


def test_two_pipelines_split_every_global_batch_and_an_epoch_can_be_replayed(shards):
    files = find_shards(str(shards / "*.tfrecord"))
    one = _batches(files)
    assert len(one) == 4 and one[0][0].shape == (4, 128, 128, 1) and one[0][1].shape == (4, 32, 32, 3)
    assert np.isfinite(one[0][0]).all() and 0.0 <= one[0][1][..., 0].min() and one[0][1][..., 0].max() <= 1.0
    parts = [_batches(files, per_replica_batch=2, input_context=tf.distribute.InputContext(2, p, 2)) for p in (0, 1)]
    for step in range(4):
        np.testing.assert_array_equal(np.concatenate([parts[0][step][0], parts[1][step][0]]), one[step][0])
        np.testing.assert_array_equal(np.concatenate([parts[0][step][1], parts[1][step][1]]), one[step][1])
    resumed = _batches(files, first_epoch=1)
    for a, b in zip(resumed, one[2:]):
        np.testing.assert_array_equal(a[0], b[0])
    assert not np.array_equal(one[0][0], one[2][0])  # each epoch draws new crops


def test_find_shards_names_what_is_wrong(shards, tmp_path):
    with pytest.raises(ValueError, match="no file matches"):
        find_shards(str(tmp_path / "*.tfrecord"))
    partial = tmp_path / "partial"
    partial.mkdir()
    (partial / "meta.json").write_bytes((shards / "meta.json").read_bytes())
    (partial / "data-00000-of-00002.tfrecord").write_bytes((shards / "data-00000-of-00002.tfrecord").read_bytes())
    with pytest.raises(ValueError, match="lacks 1 of its 2 shards"):
        find_shards(str(partial / "*.tfrecord"))


def test_train_refuses_shards_for_the_patch_classifier(capsys):
    from aicalib_tf.train import main

    assert main(["--out", "unused", "--arch", "report", "--data", "x/*.tfrecord"]) == 2
    assert capsys.readouterr().err.strip().startswith("error: --data: TFRecord shards train corner-map models")


def _broken_shards(folder, good: bytes) -> dict:
    """Files that are not data_gen shards: {name: words the error must hold}."""
    from data_gen.tfrecord import encode_example, frame_record

    other = frame_record(encode_example({"image": b"\0" * 10, "height": np.array([3]), "width": np.array([4]),
                                         "mean": np.array([0.5], np.float32), "std": np.array([0.2], np.float32),
                                         "corners": np.array([1.0, 2.0], np.float32)}))
    crc = bytearray(good)
    crc[40] ^= 0xFF
    cases = {"empty.tfrecord": (b"", "holds no records"), "text.tfrecord": (b"hello, world\n" * 3, "length checksum"),
             "short.tfrecord": (b"hi\n", "too short"), "cut.tfrecord": (good[:-9], "record 1 is cut short"),
             "crc.tfrecord": (bytes(crc), "record 0 has a bad data checksum"),
             "shape.tfrecord": (other, "record 0 has another shape")}
    for name, (data, _) in cases.items():
        (folder / name).write_bytes(data)
    return {name: words for name, (_, words) in cases.items()}


def test_files_that_are_not_shards_are_refused_naming_the_file_and_record(shards, tmp_path):
    good = (shards / "data-00000-of-00002.tfrecord").read_bytes()
    for name, words in _broken_shards(tmp_path, good).items():
        with pytest.raises(ValueError, match=words) as err:
            find_shards(str(tmp_path / name))
        assert str(tmp_path / name) in str(err.value)
    with pytest.raises(ValueError, match="a folder; give its shards"):
        find_shards(str(shards))


def test_train_on_a_broken_shard_is_one_line_and_exit_2(shards, tmp_path, capsys):
    from aicalib_tf.train import main

    _broken_shards(tmp_path, (shards / "data-00000-of-00002.tfrecord").read_bytes())
    for name in ("empty.tfrecord", "crc.tfrecord"):
        out = tmp_path / f"run-{name}"
        assert main(["--data", str(tmp_path / name), "--out", str(out), "--steps", "1", "--epochs", "1",
                     "--val-images", "1", "--workers", "1", "--quiet"]) == 2  # the validation set is rendered first
        err = [line for line in capsys.readouterr().err.splitlines() if line.startswith("error")]
        assert len(err) == 1 and name in err[0], err
        assert not (out / "model.keras").exists()
