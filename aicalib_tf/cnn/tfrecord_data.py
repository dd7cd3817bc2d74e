"""Training batches read from data_gen's TFRecord shards through ``tf.data`` (``train --data``).

The pipeline of one input pipeline (one per worker)::

    shard files (shuffled) -> interleave (parallel reads) -> repeat -> shuffle -> the epoch's examples, numbered
      -> this pipeline's share -> pixels + random crop, flip, target map (parallel) -> batch -> prefetch

Epoch ``e`` is a pure function of (files, seed, e): its file order and the examples in each window
of ``shuffle_buffer`` records are shuffled with stateless seeds drawn from (seed, e), and example ``k`` of the epoch is cropped with
``default_rng([seed, e, k, 13])``. So a run resumed at epoch ``e`` sees exactly the data it would
have seen, and the crops do not depend on how many workers share the work.

Sharing among workers (``input_context`` of ``tf.distribute``): example ``k`` goes to global
replica ``(k // b) % R`` (``b`` the per-replica batch, ``R`` the replicas), so step ``s`` of any
cluster trains on the same global batch as one worker with that batch. With ``deterministic``
every worker reads every shard (cheap: records are only decoded by their owner) and the element
order is fixed; otherwise each worker reads its own files (when there are at least as many files
as workers) and parallel stages may reorder elements for speed.
"""

from __future__ import annotations

import glob
import json
from pathlib import Path

import numpy as np
import tensorflow as tf

from aicalib_tf.cnn.corner_map import STRIDE
from aicalib_tf.cnn.training_data import CROP_SIZE, corner_crop

__all__ = ["find_shards", "check_shard", "corner_dataset", "SHUFFLE_BUFFER"]

SHUFFLE_BUFFER = 512  # examples (~0.3 MB each at 640x480)
_FEATURES = {
    "image": tf.io.FixedLenFeature([], tf.string),
    "height": tf.io.FixedLenFeature([1], tf.int64),
    "width": tf.io.FixedLenFeature([1], tf.int64),
    "mean": tf.io.FixedLenFeature([1], tf.float32),
    "std": tf.io.FixedLenFeature([1], tf.float32),
    "corners": tf.io.VarLenFeature(tf.float32),
}


def find_shards(spec: str) -> list[str]:
    """The TFRecord files of ``spec`` (globs, comma-separated), sorted.

    Raises ``ValueError`` when nothing matches, when a folder's meta.json is not a data_gen
    tfrecord dataset, or when a shard it lists is missing (a shard job not finished).
    """
    files: set[str] = set()
    for part in (p.strip() for p in str(spec).split(",")):
        if part:
            files.update(glob.glob(part))
    if not files:
        raise ValueError(f"--data {spec!r}: no file matches")
    for folder in sorted({Path(f).parent for f in files}):
        meta_path = folder / "meta.json"
        if not meta_path.is_file():
            continue  # shards copied without their meta.json are still readable
        meta = json.loads(meta_path.read_text())
        if meta.get("format") != "tfrecord":
            raise ValueError(f"--data: {meta_path} is not the meta.json of a tfrecord dataset")
        missing = [n for n in meta.get("files", []) if not (folder / n).is_file()]
        if missing:
            raise ValueError(f"--data: {folder} lacks {len(missing)} of its {len(meta['files'])} shards "
                             f"(first: {missing[0]}); render them first")
    return [check_shard(f) for f in sorted(files)]


_HEADER = 12  # a record's length (uint64) and its masked CRC (uint32); the data's masked CRC follows the data


def check_shard(path: str) -> str:
    """``path`` if it reads as a TFRecord file of data_gen examples; ``ValueError`` naming the file and
    the record otherwise.

    Every record's framing is read (its length and the length's checksum, without reading the data),
    so a truncated file, a text file or another format is refused before training starts; the first
    record's data checksum and its example (image bytes = height × width, corners in pairs) are
    checked in full. A checksum broken in a later record is reported when training reaches it.
    """
    from data_gen.tfrecord import masked_crc32c

    p = Path(path)
    if p.is_dir():
        raise ValueError(f"--data: {path}: a folder; give its shards, e.g. {p / '*.tfrecord'}")
    if not p.is_file():
        raise ValueError(f"--data: {path}: not a file")
    size, offset, count = p.stat().st_size, 0, 0
    with open(p, "rb") as f:
        while offset < size:
            head = f.read(_HEADER)
            if len(head) < _HEADER:
                what = "too short to be a TFRecord file" if count == 0 else f"record {count} is cut short (truncated file)"
                raise ValueError(f"--data: {path}: {what}")
            length = int.from_bytes(head[:8], "little")
            if masked_crc32c(head[:8]) != int.from_bytes(head[8:], "little"):
                raise ValueError(f"--data: {path}: record {count} has a bad length checksum (not a TFRecord file?)")
            if offset + _HEADER + length + 4 > size:
                raise ValueError(f"--data: {path}: record {count} is cut short (truncated file)")
            if count == 0:
                data, crc = f.read(length), f.read(4)
                if masked_crc32c(data) != int.from_bytes(crc, "little"):
                    raise ValueError(f"--data: {path}: record 0 has a bad data checksum (corrupted file)")
                _check_example(path, data)
            else:
                f.seek(length + 4, 1)
            offset += _HEADER + length + 4
            count += 1
    if count == 0:
        raise ValueError(f"--data: {path}: holds no records")
    return path


def _check_example(path: str, record: bytes) -> None:
    """ValueError unless ``record`` is one of data_gen's corner examples (see ``_FEATURES``)."""
    try:
        ex = tf.io.parse_single_example(record, _FEATURES)
        h, w = int(ex["height"][0]), int(ex["width"][0])
        n_bytes, n_xy = len(ex["image"].numpy()), int(tf.size(ex["corners"].values))
    except (tf.errors.OpError, ValueError, IndexError) as exc:
        raise ValueError(f"--data: {path}: record 0 is not a data_gen corner example "
                         f"({str(exc).splitlines()[0][:120]})") from None
    if h < 1 or w < 1 or n_bytes != h * w or n_xy % 2:
        raise ValueError(f"--data: {path}: record 0 has another shape ({n_bytes} image bytes for {w}x{h}, "
                         f"{n_xy} corner values)")


def _crop(image, stats, corners, key, squeeze: float, shrink: float, shade: float = 0.0):
    """numpy side of the map: (H, W) uint8, (2,) mean and std, (2k,) float32, (3,) int64 -> (128, 128, 1), (32, 32, 3)."""
    rng = np.random.default_rng([int(key[0]), int(key[1]), int(key[2]), 13])
    x, y = corner_crop(image, corners.reshape(-1, 2), rng, mean=float(stats[0]), std=float(stats[1]),
                       squeeze=squeeze, shrink=shrink, shade=shade)
    return x[:, :, None].astype(np.float32), y.astype(np.float32)


def corner_dataset(files: list[str], *, per_replica_batch: int, steps: int, seed: int, first_epoch: int,
                   epochs: int, input_context: tf.distribute.InputContext | None = None, deterministic: bool = True,
                   squeeze: float = 0.0, shrink: float = 0.0, shade: float = 0.0, shuffle_buffer: int = SHUFFLE_BUFFER) -> tf.data.Dataset:
    """Batches ((b, 128, 128, 1) float32, (b, 32, 32, 3) float32) of epochs ``first_epoch`` .. ``epochs - 1``.

    ``steps`` batches per epoch and replica; ``b = per_replica_batch``. ``input_context`` (from
    ``strategy.distribute_datasets_from_function``) says which share this pipeline feeds; None
    means one pipeline feeding one replica.
    """
    ctx = input_context or tf.distribute.InputContext()
    replicas, pipelines, pid = ctx.num_replicas_in_sync, ctx.num_input_pipelines, ctx.input_pipeline_id
    per_pipeline = replicas // pipelines
    per_epoch = steps * per_replica_batch * replicas  # examples per epoch, all replicas
    own_files = deterministic is False and len(files) >= pipelines > 1
    names = files[pid::pipelines] if own_files else files
    par = tf.data.AUTOTUNE

    def epoch(e):
        s = tf.cast(seed, tf.int64) * 1_000_003 + e  # stateless shuffles: tf.data's seeds must be Python ints
        order = tf.random.experimental.stateless_shuffle(tf.constant(names), seed=tf.stack([s, tf.constant(-1, tf.int64)]))
        recs = tf.data.Dataset.from_tensor_slices(order).interleave(
            tf.data.TFRecordDataset, cycle_length=min(len(names), 16), block_length=1, num_parallel_calls=par,
            deterministic=deterministic)
        recs = recs.repeat().batch(shuffle_buffer).enumerate().map(  # shuffle within windows of shuffle_buffer
            lambda w, block: tf.random.experimental.stateless_shuffle(block, seed=tf.stack([s, w]))).unbatch()
        n = per_epoch // pipelines if own_files else per_epoch
        numbered = tf.data.Dataset.zip(tf.data.Dataset.range(n), recs)
        if not own_files and pipelines > 1:  # keep the examples of this pipeline's replicas
            numbered = numbered.filter(lambda k, r: (k // per_replica_batch) % replicas // per_pipeline == pid)
        return numbered.map(lambda k, r: (e, k, r))

    def prepare(e, k, rec):
        ex = tf.io.parse_single_example(rec, _FEATURES)
        image = tf.reshape(tf.io.decode_raw(ex["image"], tf.uint8), tf.concat([ex["height"], ex["width"]], 0))
        stats = tf.concat([ex["mean"], ex["std"]], 0)
        corners = tf.sparse.to_dense(ex["corners"])
        key = tf.stack([tf.cast(seed, tf.int64), e, k])
        x, y = tf.numpy_function(lambda i, st, c, kk: _crop(i, st, c, kk, squeeze, shrink, shade), [image, stats, corners, key],
                                 [tf.float32, tf.float32], stateful=False)
        x.set_shape((CROP_SIZE, CROP_SIZE, 1))
        y.set_shape((CROP_SIZE // STRIDE, CROP_SIZE // STRIDE, 3))
        return x, y

    ds = tf.data.Dataset.range(first_epoch, epochs).flat_map(epoch)
    ds = ds.map(prepare, num_parallel_calls=par, deterministic=deterministic)
    ds = ds.batch(per_replica_batch, drop_remainder=True).prefetch(par)
    options = tf.data.Options()
    options.deterministic = deterministic
    options.experimental_distribute.auto_shard_policy = tf.data.experimental.AutoShardPolicy.OFF  # shared above
    return ds.with_options(options)
