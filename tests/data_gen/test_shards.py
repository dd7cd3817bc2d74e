"""python -m data_gen --format tfrecord: framing, byte-identical shards however they are split, bounds."""

import itertools
import json
import struct

import pytest

from data_gen.__main__ import main
from data_gen.dataset import imap_ordered
from data_gen.tfrecord import crc32c, encode_example, frame_record, masked_crc32c

ARGS = ["--count", "5", "--preset", "train", "--seed", "3", "--size", "160x120", "--no-progress", "--format", "tfrecord"]


def test_crc32c_matches_the_published_check_values():
    assert crc32c(b"123456789") == 0xE3069283  # the CRC-32C check value
    assert crc32c(b"") == 0
    assert crc32c(bytes(32)) == 0x8A9136AA  # RFC 3720, B.4: 32 bytes of zeros
    assert crc32c(b"\xff" * 32) == 0x62A8AB43
    assert crc32c(bytes(range(32))) == 0x46DD794E
    long = bytes(range(256)) * 40  # many lanes, and a length that is no power of two
    bitwise = 0xFFFFFFFF
    for byte in long[:3001]:
        bitwise ^= byte
        for _ in range(8):
            bitwise = (bitwise >> 1) ^ (0x82F63B78 if bitwise & 1 else 0)
    assert crc32c(long[:3001]) == bitwise ^ 0xFFFFFFFF


def test_a_record_is_length_crc_data_crc():
    rec = frame_record(b"abc")
    assert struct.unpack("<Q", rec[:8])[0] == 3 and rec[12:15] == b"abc"
    assert struct.unpack("<I", rec[8:12])[0] == masked_crc32c(rec[:8])
    assert struct.unpack("<I", rec[15:])[0] == masked_crc32c(b"abc")


def test_examples_are_written_in_one_order():
    assert encode_example({"b": b"x", "a": [1, 2]}) == encode_example({"a": [1, 2], "b": b"x"})
    with pytest.raises(TypeError):
        encode_example({"a": ["text"]})


def test_a_shard_rendered_alone_is_the_shard_of_a_full_run(tmp_path):
    assert main(["--out", str(tmp_path / "all"), *ARGS, "--shards", "2"]) == 0
    assert main(["--out", str(tmp_path / "one"), *ARGS, "--shard", "1/2", "--workers", "2"]) == 0
    assert main(["--out", str(tmp_path / "all"), *ARGS, "--shard", "1/2"]) == 0  # a job run again: same bytes
    full = {p.name: p.read_bytes() for p in (tmp_path / "all").iterdir()}
    alone = {p.name: p.read_bytes() for p in (tmp_path / "one").iterdir()}
    assert sorted(full) == ["data-00000-of-00002.tfrecord", "data-00001-of-00002.tfrecord", "meta.json"]
    assert sorted(alone) == ["data-00001-of-00002.tfrecord", "meta.json"]
    assert alone["data-00001-of-00002.tfrecord"] == full["data-00001-of-00002.tfrecord"]
    assert alone["meta.json"] == full["meta.json"]
    meta = json.loads(full["meta.json"])
    assert meta["format"] == "tfrecord" and meta["examples"] == [2, 3] and "image" in meta["schema"]


@pytest.mark.parametrize(
    "args, message",
    [
        (["--count", "1000000000", "--preset", "train"], "--count must be at most 1000000, got 1000000000"),
        (["--count", "1000000000", "--preset", "train", "--format", "tfrecord"], "--count must be at most"),
        (["--count", "100000", "--preset", "train", "--format", "tfrecord", "--shards", "2"], "use --shards"),
        (["--count", "4", "--preset", "train", "--format", "tfrecord", "--shard", "4/4"], "--shard"),
        (["--count", "4", "--preset", "train", "--format", "tfrecord", "--shard", "1/2", "--shards", "3"], "disagrees"),
        (["--count", "4", "--preset", "train", "--shards", "2"], "need --format tfrecord"),
    ],
)
def test_bad_shard_arguments_exit_2_with_one_line(tmp_path, capsys, args, message):
    assert main(["--out", str(tmp_path / "ds"), *args]) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and len(err.splitlines()) == 1
    assert not (tmp_path / "ds").exists()


def test_a_folder_of_another_dataset_is_refused(tmp_path, capsys):
    assert main(["--out", str(tmp_path / "ds"), *ARGS, "--shard", "0/2"]) == 0
    assert main(["--out", str(tmp_path / "ds"), *ARGS[:-2], "--seed", "4", "--format", "tfrecord", "--shard", "1/2"]) == 2
    assert "holds another dataset" in capsys.readouterr().err


def test_jobs_are_read_lazily_whatever_the_workers():
    for workers in (1, 2):
        results = imap_ordered(abs, itertools.count(-3), workers=workers, window=2)  # an endless stream
        assert list(itertools.islice(results, 5)) == [3, 2, 1, 0, 1]
        results.close()
