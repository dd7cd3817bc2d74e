"""Training and validation data for the corner CNNs, from data_gen (Keras ``PyDataset``).

A run first renders a *pool* of data_gen images in memory (seeded, in worker processes): full
640×480 scenes of the ``train`` preset with every lens, pose and degradation, plus board-free
clutter images. Batches are then cut from the pool on the fly, so every epoch sees new crops:

* corner-map model: random 128×128 crops (most of them around board corners), a random one of the
  8 flips/rotations, and a random grey inversion (an inverted X-junction is still one);
* patch classifier: balanced 32×32 patches, half centred on corners and half negatives, of which
  half are hard negatives (saddle-point candidates away from any corner: edges, T- and L-junctions,
  text, blobs, noise) and half are random places.

Checker-like distractor patches are left out of training images: their X-junctions are real, so
a local detector should fire on them; telling them from the board is the grid assembly's job.

Batch ``i`` of epoch ``e`` depends only on (seed, e, i), so the same seed gives the same data order.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import keras
import numpy as np
from tqdm import tqdm

from aicalib_tf.cnn.corner_map import STRIDE, encode_corners, standardize
from aicalib_tf.cnn.model import PATCH_SIZE
from aicalib_tf.detect.corners.candidates import saddle_points
from data_gen.dataset import iter_samples
from data_gen.presets import get_preset

__all__ = ["Pool", "parse_mix", "render_pool", "CornerMapBatches", "PatchBatches", "corner_crop", "CROP_SIZE"]

CROP_SIZE = 128
IMAGE_SIZE = (640, 480)
BOARD_FREE_FRACTION = 0.1
MIX_INDEX_STRIDE = 1_000_000  # preset k of a mix renders indices k·stride + i: no scene repeats another's


def parse_mix(spec: str) -> list[tuple[str, float]]:
    """A pool's presets and their shares from ``"train"`` or ``"train:0.8,distorted:0.2"``.

    A name without a share gets 1; shares are normalised to sum to 1. Raises ``ValueError`` naming
    the bad part (unknown preset, share not a positive number, a preset twice).
    """
    from data_gen.presets import PRESETS

    out: list[tuple[str, float]] = []
    for part in str(spec).split(","):
        name, _, share = part.strip().partition(":")
        if name not in PRESETS:
            raise ValueError(f"unknown preset {name!r} in {spec!r}; choose from: {', '.join(PRESETS)}")
        if name in (n for n, _ in out):
            raise ValueError(f"preset {name!r} appears twice in {spec!r}")
        try:
            w = float(share) if share else 1.0
        except ValueError:
            raise ValueError(f"share {share!r} of preset {name!r} is not a number") from None
        if not (w > 0 and np.isfinite(w)):
            raise ValueError(f"share of preset {name!r} must be > 0, got {share!r}")
        out.append((name, w))
    total = sum(w for _, w in out)
    return [(n, w / total) for n, w in out]


def _split(count: int, shares: list[float]) -> list[int]:
    """``count`` items split by ``shares`` (largest remainders), summing to ``count``."""
    raw = np.asarray(shares) * count
    n = np.floor(raw).astype(int)
    for k in np.argsort(-(raw - n), kind="stable")[: count - int(n.sum())]:
        n[k] += 1
    return [int(v) for v in n]


@dataclass(frozen=True)
class Pool:
    """Rendered images held in memory.

    images : (N, H, W) uint8. corners : N arrays (k, 2) float32, the visible corners (x, y) px.
    mean, std : (N,) float32 grey statistics of each image (for standardising crops like whole images).
    """

    images: np.ndarray
    corners: list
    mean: np.ndarray
    std: np.ndarray

    def __len__(self) -> int:
        return len(self.images)

    def standardized(self, i: int, img: np.ndarray) -> np.ndarray:
        """A crop of image ``i`` standardised with the whole image's statistics."""
        return standardize(img, self.mean[i], self.std[i])


def render_pool(count: int, seed: int, *, preset: str = "train", workers: int = 1, progress: bool = True,
                size: tuple[int, int] = IMAGE_SIZE) -> Pool:
    """Render ``count`` images: ~90% board scenes of ``preset`` and ~10% board-free clutter, all seeded.

    preset : one data_gen preset, or a mix ``"train:0.8,distorted:0.2"`` (:func:`parse_mix`): the
        board scenes are split by the shares, preset k of the mix rendering indices from
        ``k · MIX_INDEX_STRIDE`` (a single preset renders exactly what it did before mixes).
    Distractor checkers are switched off (see the module docstring).
    """
    if count < 1:
        raise ValueError(f"pool needs at least 1 image, got {count}")
    mix = parse_mix(preset)
    clutter = get_preset("clutter", checker_distractors=(0.0, 0.0))
    n_free = int(round(BOARD_FREE_FRACTION * count)) if count >= 10 else 0
    w, h = size
    images = np.empty((count, h, w), np.uint8)
    corners = []
    jobs = [(get_preset(name, checker_distractors=(0.0, 0.0)), range(k * MIX_INDEX_STRIDE, k * MIX_INDEX_STRIDE + n))
            for k, ((name, _), n) in enumerate(zip(mix, _split(count - n_free, [s for _, s in mix])))]
    jobs.append((clutter, range(n_free)))
    bar = tqdm(total=count, desc=f"rendering {preset} pool", unit="img", disable=not progress)
    k = 0
    for p, indices in jobs:
        for s in iter_samples(p, seed, indices, size=size, workers=workers):
            images[k] = s.image
            corners.append(s.corners[s.visible].astype(np.float32) if s.label["has_board"] else np.zeros((0, 2), np.float32))
            k += 1
            bar.update()
    bar.close()
    mean = np.array([img.mean() for img in images], np.float32)  # per image: no float copy of the pool
    std = np.array([img.std() for img in images], np.float32)
    return Pool(images, corners, mean, std)


def _dihedral(img: np.ndarray, pts: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """Apply flip/rotation ``k`` in 0..7 to a square image (S, S) and its points (n, 2) (x, y)."""
    s = img.shape[0] - 1
    x, y = pts[:, 0], pts[:, 1]
    if k & 1:  # transpose
        img, x, y = img.T, y, x
    if k & 2:  # flip left-right
        img, x = img[:, ::-1], s - x
    if k & 4:  # flip up-down
        img, y = img[::-1, :], s - y
    return np.ascontiguousarray(img), np.stack([x, y], axis=1)


def squeeze_matrix(angle: float, ratio: float) -> np.ndarray:
    """(2, 2) area-preserving stretch: ``sqrt(ratio)``× along the direction at ``angle`` rad and
    ``1/sqrt(ratio)``× across it (symmetric, determinant 1)."""
    c, s = np.cos(angle), np.sin(angle)
    rot = np.array([[c, -s], [s, c]])
    return rot @ np.diag([np.sqrt(ratio), 1.0 / np.sqrt(ratio)]) @ rot.T


def _warp_crop(img: np.ndarray, pts: np.ndarray, a: np.ndarray, centre, size: int) -> tuple[np.ndarray, np.ndarray]:
    """A (size, size) crop of ``img`` whose pixel offsets d from the crop's centre sample the image
    at ``centre + a @ d`` (bilinear, edges replicated), and ``pts`` (n, 2) (x, y) moved with it.

    ``a`` maps crop offsets to image offsets, so the image seen in the crop is squeezed by ``a``'s
    larger singular value in its direction. Pixel centres at integers, as in OpenCV.
    """
    c_out = np.full(2, (size - 1) / 2.0)
    c_src = np.asarray(centre, np.float64)
    m = np.hstack([a, (c_src - a @ c_out)[:, None]])
    crop = cv2.warpAffine(img, m, (size, size), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                          borderMode=cv2.BORDER_REPLICATE)
    local = (np.asarray(pts, np.float64) - c_src) @ np.linalg.inv(a).T + c_out
    return crop, local.astype(np.float32)


def shade_crop(crop: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """``crop`` (H, W) grey 0..255 under a random light and blur law, as at a lens's dark rim:
    Gaussian blur (σ 0–2.5 px), a smooth light fall-off (gain log-uniform 0.05–1 at the centre,
    changing up to e^±1.5 across the crop along a random direction, capped at 1), then grey noise
    (σ 0.5–4 levels) and rounding to whole grey levels, as a camera records them. Returns (H, W)
    float32 in 0..255. Corners keep their places (the blur is symmetric, the light only scales)."""
    g = crop.astype(np.float32)
    sigma = rng.uniform(0.0, 2.5)
    if sigma > 0.3:
        g = cv2.GaussianBlur(g, (0, 0), sigma, borderType=cv2.BORDER_REPLICATE)
    h, w = g.shape
    a = rng.uniform(0.0, 2.0 * np.pi)
    u = ((np.arange(w, dtype=np.float32)[None, :] - (w - 1) / 2) * np.cos(a)
         + (np.arange(h, dtype=np.float32)[:, None] - (h - 1) / 2) * np.sin(a)) / max(h, w)
    gain = np.exp(rng.uniform(np.log(0.05), 0.0) + rng.uniform(-3.0, 3.0) * u)
    g = g * np.minimum(gain, 1.0) + rng.normal(0.0, rng.uniform(0.5, 4.0), g.shape).astype(np.float32)
    return np.clip(np.rint(g), 0.0, 255.0).astype(np.float32)


def halve(img: np.ndarray, pts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``img`` (H, W) at half size, each pixel the mean of a 2×2 block ((H // 2, W // 2), same
    dtype), and its points (n, 2) (x, y) moved with it: x' = (x + 0.5) / 2 − 0.5."""
    h, w = img.shape[0] // 2, img.shape[1] // 2
    small = cv2.resize(img[: 2 * h, : 2 * w], (w, h), interpolation=cv2.INTER_AREA)
    return small, ((np.asarray(pts, np.float32) + 0.5) / 2 - 0.5).astype(np.float32)


class _PoolBatches(keras.utils.PyDataset):
    """``steps`` batches a epoch cut from a pool; batch ``idx`` of epoch ``epoch`` is seeded by both."""

    def __init__(self, pool: Pool, *, batch_size: int, steps: int, seed: int, epoch: int = 0, **kwargs):
        super().__init__(**kwargs)
        self.pool, self.batch_size, self.steps, self.seed, self.epoch = pool, batch_size, steps, seed, epoch

    def __len__(self) -> int:
        return self.steps

    def on_epoch_end(self) -> None:
        self.epoch += 1


class CornerMapBatches(_PoolBatches):
    """Batches (B, 128, 128, 1) float32 -> corner-map targets (B, 32, 32, 3) for the default model.

    corner_bias : share of crops placed to contain a board corner.
    squeeze : share of crops warped by :func:`squeeze_matrix` (area-preserving, squeezed up to
        ``max_squeeze``× in a random direction): X-junctions with acute angles and thin squares,
        as at the edge of a wide lens or under steep tilt. 0 (the default) draws exactly the crops
        drawn before the option existed.
    shrink : share of crops cut from the image shrunk to half size (:func:`halve`, block means):
        boards with squares half as wide, integrated over the pixels as a camera would. 0 (the
        default) draws exactly the crops drawn before the option existed.
    shade : share of crops under a random light fall-off, blur and noise (:func:`shade_crop`):
        dim, low-contrast, soft corners as at a fisheye's vignetted rim, whatever the scene's lens.
        0 (the default) draws exactly the crops drawn before the option existed.
    """

    def __init__(self, pool: Pool, *, corner_bias: float = 0.6, squeeze: float = 0.0, max_squeeze: float = 3.0,
                 shrink: float = 0.0, shade: float = 0.0, **kwargs):
        super().__init__(pool, **kwargs)
        self.corner_bias, self.squeeze, self.max_squeeze, self.shrink = corner_bias, squeeze, max_squeeze, shrink
        self.shade = shade

    def __getitem__(self, idx: int):
        rng = np.random.default_rng([self.seed, self.epoch, idx, 7])
        s = CROP_SIZE
        x = np.empty((self.batch_size, s, s, 1), np.float32)
        y = np.empty((self.batch_size, s // STRIDE, s // STRIDE, 3), np.float32)
        for b in range(self.batch_size):
            i = int(rng.integers(len(self.pool)))
            x[b, :, :, 0], y[b] = corner_crop(self.pool.images[i], self.pool.corners[i], rng,
                                              mean=self.pool.mean[i], std=self.pool.std[i],
                                              corner_bias=self.corner_bias, squeeze=self.squeeze,
                                              max_squeeze=self.max_squeeze, shrink=self.shrink, shade=self.shade)
        return x, y


def corner_crop(img: np.ndarray, pts: np.ndarray, rng: np.random.Generator, *, mean: float, std: float,
                corner_bias: float = 0.6, squeeze: float = 0.0, max_squeeze: float = 3.0,
                shrink: float = 0.0, shade: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """One training pair for the corner-map model from one image (see :class:`CornerMapBatches`).

    img : (H, W) uint8, H, W >= 128. pts : (k, 2) float32 visible corners (x, y) px.
    mean, std : the whole image's grey statistics (the crop is standardised with them).
    Returns the crop (128, 128) float32 and its target (32, 32, 3) float32.
    """
    s = CROP_SIZE
    if shrink > 0 and rng.random() < shrink:
        img, pts = halve(img, pts)
    h, w = img.shape
    if len(pts) and rng.random() < corner_bias:
        cx, cy = pts[int(rng.integers(len(pts)))]
        x0 = int(np.clip(cx - rng.uniform(8, s - 8), 0, w - s))
        y0 = int(np.clip(cy - rng.uniform(8, s - 8), 0, h - s))
    else:
        x0, y0 = int(rng.integers(w - s + 1)), int(rng.integers(h - s + 1))
    if squeeze > 0 and rng.random() < squeeze:
        a = squeeze_matrix(rng.uniform(0.0, np.pi), np.exp(rng.uniform(0.0, np.log(max_squeeze))))
        crop, local = _warp_crop(img, pts, a, (x0 + (s - 1) / 2, y0 + (s - 1) / 2), s)
    else:
        crop, local = img[y0 : y0 + s, x0 : x0 + s], pts - np.array([x0, y0], np.float32)
    if shade > 0 and rng.random() < shade:
        crop = shade_crop(crop, rng)
    crop, local = _dihedral(standardize(crop, mean, std), local, int(rng.integers(8)))
    if rng.random() < 0.5:
        crop = -crop
    return crop, encode_corners(local, (s, s))


def _extract_patches(image: np.ndarray, points: np.ndarray) -> np.ndarray:
    """:func:`aicalib_tf.cnn.inference.extract_patches`, imported on first use (it imports TensorFlow,
    which the corner-map batches do not need)."""
    from aicalib_tf.cnn.inference import extract_patches

    return extract_patches(image, points)


class PatchBatches(_PoolBatches):
    """Balanced batches (B, 32, 32, 1) float32 -> (B, 1) labels for the report's patch classifier."""

    def __init__(self, pool: Pool, **kwargs):
        super().__init__(pool, **kwargs)
        self.hard = [self._hard_negatives(i) for i in range(len(pool))]
        self.with_corners = [i for i in range(len(pool)) if len(pool.corners[i])] or [0]

    def _hard_negatives(self, i: int) -> np.ndarray:
        cand = saddle_points(self.pool.images[i], max_points=300)
        pts = self.pool.corners[i]
        if len(pts) == 0 or len(cand) == 0:
            return cand
        d2 = ((cand[:, None, :] - pts[None, :, :]) ** 2).sum(-1).min(axis=1)
        return cand[d2 > 3.0**2]

    def __getitem__(self, idx: int):
        rng = np.random.default_rng([self.seed, self.epoch, idx, 11])
        n = self.batch_size
        x = np.empty((n, PATCH_SIZE, PATCH_SIZE, 1), np.float32)
        y = (np.arange(n) < n // 2).astype(np.float32)[:, None]
        for b in range(n):
            if y[b, 0] == 1.0:
                i = self.with_corners[int(rng.integers(len(self.with_corners)))]
                pts = self.pool.corners[i]
                p = np.rint(pts[int(rng.integers(len(pts)))]).astype(np.int64)
            else:
                i = int(rng.integers(len(self.pool)))
                h, w = self.pool.images[i].shape
                hard = self.hard[i]
                if len(hard) and rng.random() < 0.5:
                    p = hard[int(rng.integers(len(hard)))].astype(np.int64)
                else:
                    p = np.array([rng.integers(w), rng.integers(h)])
                    pts = self.pool.corners[i]
                    if len(pts) and (((pts - p) ** 2).sum(1) < 9.0).any():
                        p = p + 4  # nudge off a corner; rare
            patch = self.pool.standardized(i, _extract_patches(self.pool.images[i], p[None])[0])
            k = int(rng.integers(8))
            # corner at (16, 16) ± 0.5; the flips keep it within a pixel of the centre
            patch, _ = _dihedral(patch, np.zeros((0, 2), np.float32), k)
            x[b, :, :, 0] = -patch if rng.random() < 0.5 else patch
        return x, y
