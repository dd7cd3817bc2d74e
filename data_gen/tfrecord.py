"""TFRecord files written without TensorFlow: record framing, CRC-32C and ``tf.train.Example`` protos.

data_gen may import only numpy, OpenCV and the geometry of aicalib_tf (``tests/test_architecture.py``),
so it cannot call TensorFlow's writer. The format is small and documented
(https://www.tensorflow.org/tutorials/load_data/tfrecord): each record is

    uint64 length (little endian) | uint32 masked CRC-32C of the length | data | uint32 masked CRC-32C of data

and ``data`` is a serialised ``tf.train.Example`` (protobuf: a map from feature names to a bytes,
float or int64 list). TensorFlow's reader checks both CRCs, so a wrong byte fails loudly; the tests
read these files back with ``tf.data``.

>>> hex(crc32c(b"123456789"))
'0xe3069283'
"""

from __future__ import annotations

import struct
from functools import lru_cache

import numpy as np

__all__ = ["crc32c", "masked_crc32c", "frame_record", "encode_example"]

_POLY = 0x82F63B78  # CRC-32C (Castagnoli), reflected
_LANE = 512  # bytes each numpy lane runs through the table; lanes are combined by GF(2) shifts


def _table() -> np.ndarray:
    t = np.arange(256, dtype=np.uint32)
    for _ in range(8):
        t = np.where(t & 1, (t >> 1) ^ np.uint32(_POLY), t >> 1).astype(np.uint32)
    return t


_TABLE = _table()
_BITS = np.arange(32, dtype=np.uint32)


def _apply(op: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Apply the GF(2)-linear map ``op`` ((32,) uint32: the image of each bit) to values ``v`` (n,) uint32."""
    bits = (v[:, None] >> _BITS[None, :]) & np.uint32(1)
    return np.bitwise_xor.reduce(bits * op[None, :], axis=1).astype(np.uint32)


@lru_cache(maxsize=64)
def _zeros_op(n: int) -> np.ndarray:
    """The map that feeding ``n`` zero bytes applies to a CRC register, (32,) uint32 (read-only)."""
    if n == 0:
        op = np.left_shift(np.uint32(1), _BITS)
    elif n == 1:
        c = np.left_shift(np.uint32(1), _BITS)
        op = (_TABLE[c & np.uint32(0xFF)] ^ (c >> np.uint32(8))).astype(np.uint32)
    else:
        half = _zeros_op(n // 2)
        op = _apply(half, half)  # half after half
        if n % 2:
            op = _apply(_zeros_op(1), op)
    op.setflags(write=False)
    return op


def crc32c(data: bytes) -> int:
    """CRC-32C of ``data`` (as ``google_crc32c`` / TensorFlow compute it), in numpy.

    The message is cut into lanes of 512 bytes that run through the byte table side by side; the
    lanes' registers are then folded pairwise, each left one shifted over its right neighbour's
    length (a linear map on 32 bits). About 10 ms for a 300 kB image.
    """
    a = np.frombuffer(bytes(data), np.uint8)
    n = len(a)
    lanes = max(1, -(-n // _LANE))
    lanes = 1 << (lanes - 1).bit_length()
    padded = np.zeros(lanes * _LANE, np.uint8)  # leading zeros leave a zero register at zero
    padded[lanes * _LANE - n:] = a
    block = padded.reshape(lanes, _LANE).T.astype(np.uint32)
    c = np.zeros(lanes, np.uint32)
    for col in block:
        c = _TABLE[(c ^ col) & np.uint32(0xFF)] ^ (c >> np.uint32(8))
    span = _LANE
    while len(c) > 1:
        c = _apply(_zeros_op(span), c[0::2]) ^ c[1::2]
        span *= 2
    init = _apply(_zeros_op(n), np.array([0xFFFFFFFF], np.uint32))[0]  # the all-ones start, shifted over the data
    return int(c[0] ^ init ^ np.uint32(0xFFFFFFFF))


def masked_crc32c(data: bytes) -> int:
    """TFRecord's masked CRC: rotate right by 15 bits and add 0xA282EAD8 (mod 2³²)."""
    crc = crc32c(data)
    return (((crc >> 15) | (crc << 17)) + 0xA282EAD8) & 0xFFFFFFFF


def frame_record(data: bytes) -> bytes:
    """One TFRecord: length, its masked CRC, ``data``, its masked CRC."""
    length = struct.pack("<Q", len(data))
    return length + struct.pack("<I", masked_crc32c(length)) + data + struct.pack("<I", masked_crc32c(data))


def _varint(n: int) -> bytes:
    out = bytearray()
    while True:
        b = n & 0x7F
        n >>= 7
        if n:
            out.append(b | 0x80)
        else:
            out.append(b)
            return bytes(out)


def _field(number: int, payload: bytes) -> bytes:
    """A length-delimited protobuf field (wire type 2)."""
    return _varint(number << 3 | 2) + _varint(len(payload)) + payload


def _feature(value) -> bytes:
    """A ``tf.train.Feature``: bytes -> BytesList (1), float array -> FloatList (2), int array -> Int64List (3)."""
    if isinstance(value, bytes):
        return _field(1, _field(1, value))
    arr = np.asarray(value)
    if arr.dtype.kind == "f":
        return _field(2, _field(1, arr.astype("<f4").tobytes()))  # packed floats
    if arr.dtype.kind in "iub":
        packed = b"".join(_varint(int(v) & 0xFFFFFFFFFFFFFFFF) for v in arr.reshape(-1))
        return _field(3, _field(1, packed))
    raise TypeError(f"feature values must be bytes, floats or ints, got {arr.dtype}")


def encode_example(features: dict) -> bytes:
    """A serialised ``tf.train.Example`` of ``{name: bytes | float array | int array}``.

    Features are written in sorted name order, so equal inputs give equal bytes.
    """
    entries = b"".join(_field(1, _field(1, name.encode()) + _field(2, _feature(features[name])))
                       for name in sorted(features))
    return _field(1, entries)
