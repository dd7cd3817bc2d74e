"""Close-up fisheye boards by family: one law of data_gen's ``closeup_laws`` pinned at a time, full boards per family.

    python benchmarks/closeup_families.py [--split tune|held-out|both] [--count 12] [--seed 301]
                                          [--families NAME,...] [--show]

Each family is data_gen's ``closeup_laws`` (circular 150–210° fisheyes, the paper over 30–90% of
the image circle and up to its rim, rim vignetting, field blur, narrow margins, low contrast,
checker distractors in clutter; 640×480 unless named ``-hd``) with one law pinned, the others
drawn as the preset draws them:

- ``cover-30-50``, ``cover-50-70``, ``cover-70-90``: the paper's share of the image circle;
- ``fov-150-180``, ``fov-180-210``: the lens's full field of view;
- ``vig-cos4``, ``vig-poly``, ``vig-hard``: the light's fall towards the rim (cos⁴, polynomial, a
  hard black rim), at full strength (0.97–1.0: black at the circle);
- ``blur-linear``, ``blur-quadratic``: field blur growing as ρ or ρ² to σ 2–3.5 px at the rim;
- ``margin-narrow``: 0.05–0.2 squares of white paper about the outer squares;
- ``contrast-low``: black 0.25–0.4, white 0.5–0.65 (a fifth to a third of the full swing);
- ``rim-reach``, ``rim-reach-hd``: 180–210° lenses, kept only when the outer squares reach 85° or
  more off the optical axis (squeezed to a few px, darkened to black, up to and past 90°);
- ``rim-deep``: 180–210° lenses, kept only when an inner corner itself lies 86° or more off axis;
- ``margin-none``: ``rim-reach`` with 0–0.03 squares of paper about the outer squares (a printed
  texture with no border: the outer squares meet the background).

The image-formation families are ``rim-reach`` (the same scenes, image by image) with one law of a real
camera or another renderer added (:mod:`data_gen.sensor`), the others as ``rim-reach`` draws them:

- ``edge-soft``: the image circle's edge a cosine ramp over its outer 2–8%;
- ``rim-black-early``: the light black at 90–97% of the circle's radius, over a ramp of 10–25%;
- ``defocus-disc``: the field blur's Gaussian replaced by a disc (pillbox) of the same spread (radius 2σ);
- ``ca-lateral``: lateral chromatic aberration, R and B 1–3 px apart from G at the rim, turned into grey;
- ``astig-radial``: blur along the radius of σ 2–4 px at the rim (0–1 px along the circle), growing as
  ρ^1.5–ρ^3: a fisheye's astigmatism, or a renderer's radial blur, on top of the field blur;
- ``mosaic``: an RGGB mosaic with a raw colour cast, demosaiced bilinearly or edge-aware, white balanced;
- ``noise-poisson``: photon noise of 20–200 photons at white under the read noise;
- ``tone-srgb``: the paper's reflectance (black 0.01–0.1, white 0.3–0.9) and the rim's fall-off in linear
  light, encoded by the sRGB curve;
- ``sharpen``: an unsharp mask (amount 0.5–1.5, σ 0.8–2 px) with its halos;
- ``alias-point``: the board point-sampled, one ray through each pixel's centre (no anti-aliasing: the
  squeezed outer squares' edges step by whole pixels), then the field blur and noise as drawn;
- ``camera-chain``: all of these at once as a camera makes them (disc defocus, lateral CA, photon
  noise, mosaic, sRGB, mild sharpening, JPEG at quality 70–95), the circle edge soft.

The lens family is the split: ``tune`` draws equidistant (Kannala–Brandt) lenses, the family the
detector's rim stages were tuned on; ``held-out`` draws Double Sphere and EUCM lenses. ``--seed``
draws other scenes (the families' renders are not the evaluate conditions' seed-41 ones).
Each image goes through :func:`aicalib_tf.detect_corners` with the 9×6 pattern, scored as evaluate
scores it (hit: every corner within 2 px; wrong: a full board with a corner further off). Prints
one row per family (hits, wrong, misses, the misses' blamed stage by ``stage_misses.trace``) and
the total; ``--show`` one line per miss.
"""

from __future__ import annotations

import math
import sys
from collections import Counter
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from aicalib_tf.bench.conditions import PATTERN, VGA, Condition  # noqa: E402
from data_gen.presets import Rule, get_preset  # noqa: E402

SPLITS = {"tune": "fisheye", "held-out": ("ds", "eucm")}
RIM_DEG = 85.0  # rim-reach families: the least off-axis angle of the outer squares' farthest corner
DEEP_DEG = 86.0  # rim-deep: the least off-axis angle of the farthest inner corner


def _rules(vig: dict | None = None, blur: dict | None = None, disc: bool = False,
           extra: tuple[Rule, ...] = ()) -> tuple[Rule, ...]:
    """closeup_laws' rules with the vignetting or the blur rule's parameters replaced; with ``disc``, the field
    blur a disc of radius 2σ (the same draws: both rules draw three parameters in the same order); then ``extra``."""
    out = []
    for r in get_preset("closeup_laws").rules:
        new = vig if r.name == "rim_vignetting" else blur if r.name == "field_blur" else None
        if disc and r.name == "field_blur":
            p = dict(r.params)
            out.append(Rule.of("field_defocus", r.p, power=p["power"],
                               radius_centre=tuple(2 * v for v in p["sigma_centre"]),
                               radius_rim=tuple(2 * v for v in p["sigma_rim"])))
            continue
        out.append(r if new is None else Rule.of(r.name, r.p, **{**dict(r.params), **new}))
    return tuple(out) + tuple(extra)


LINEAR_PAPER = {"paper_black": (0.01, 0.1), "paper_white": (0.3, 0.9)}  # reflectances in linear light
_SOFT_EDGE = Rule.of("circle_edge", black_at=1.0, width=(0.02, 0.08))


def _camera_chain() -> tuple[Rule, ...]:
    """rim-reach's rules as a camera's: disc defocus, lateral CA, photon noise, mosaic, sRGB, sharpening, JPEG."""
    return _rules(disc=True, extra=(
        _SOFT_EDGE, Rule.of("lateral_ca", shift=(0.5, 2.0), power=(1.0, 2.0)),
        Rule.of("shot_noise", photons=(50.0, 500.0)),
        Rule.of("bayer_demosaic", gain_r=(0.4, 0.8), gain_b=(0.5, 0.9), method=("bilinear", "edge")),
        Rule.of("tone_curve", law="srgb", gamma=2.2), Rule.of("unsharp", 0.5, amount=(0.3, 1.0), sigma=1.0),
        Rule.of("jpeg", quality=(70, 95))))


def families() -> dict[str, dict]:
    """{name: overrides of the closeup_laws preset (``pose`` as PoseConfig fields), "size", "rim"}."""
    def vig(law):
        return {"rules": _rules(vig={"law": law, "strength": (0.97, 1.0)})}

    def blur(power):
        return {"rules": _rules(blur={"power": power, "sigma_rim": (2.0, 3.5)})}

    return {
        "cover-30-50": {"pose": {"circle_fill": (0.3, 0.5)}},
        "cover-50-70": {"pose": {"circle_fill": (0.5, 0.7)}},
        "cover-70-90": {"pose": {"circle_fill": (0.7, 0.9)}},
        "fov-150-180": {"fisheye_fov_deg": (150.0, 180.0)},
        "fov-180-210": {"fisheye_fov_deg": (180.0, 210.0)},
        "vig-cos4": vig("cos4"), "vig-poly": vig("poly"), "vig-hard": vig("hard"),
        "blur-linear": blur(1.0), "blur-quadratic": blur(2.0),
        "margin-narrow": {"margin_range": (0.05, 0.2)},
        "contrast-low": {"paper_black": (0.25, 0.4), "paper_white": (0.5, 0.65)},
        "rim-reach": {"fisheye_fov_deg": (180.0, 210.0), "rim": True},
        "rim-reach-hd": {"fisheye_fov_deg": (180.0, 210.0), "rim": True, "size": (1280, 960)},
        "rim-deep": {"fisheye_fov_deg": (180.0, 210.0), "rim": DEEP_DEG},
        "margin-none": {"fisheye_fov_deg": (180.0, 210.0), "rim": True, "margin_range": (0.0, 0.03)},
        **{name: {"fisheye_fov_deg": (180.0, 210.0), "rim": True, **spec} for name, spec in image_laws().items()},
    }


def image_laws() -> dict[str, dict]:
    """{name: overrides of rim-reach}: the image-formation families (one law of :mod:`data_gen.sensor` each)."""
    def plus(*rules):
        return {"rules": _rules(extra=rules)}

    return {
        "edge-soft": plus(_SOFT_EDGE),
        "rim-black-early": plus(Rule.of("circle_edge", black_at=(0.9, 0.97), width=(0.1, 0.25))),
        "defocus-disc": {"rules": _rules(disc=True)},
        "ca-lateral": plus(Rule.of("lateral_ca", shift=(1.0, 3.0), power=(1.0, 2.0))),
        "astig-radial": plus(Rule.of("astigmatism", sigma_radial=(2.0, 4.0), sigma_tangential=(0.0, 1.0),
                                     power=(1.5, 3.0))),
        "mosaic": plus(Rule.of("bayer_demosaic", gain_r=(0.4, 0.8), gain_b=(0.5, 0.9), method=("bilinear", "edge"))),
        "noise-poisson": plus(Rule.of("shot_noise", photons=(20.0, 200.0))),
        "tone-srgb": {**plus(Rule.of("tone_curve", law="srgb", gamma=2.2)), **LINEAR_PAPER},
        "sharpen": plus(Rule.of("unsharp", amount=(0.5, 1.5), sigma=(0.8, 2.0))),
        "alias-point": {"antialias": False},
        "camera-chain": {"rules": _camera_chain(), **LINEAR_PAPER},
    }


def family_condition(name: str, split: str, seed: int) -> Condition:
    """The evaluate :class:`~aicalib_tf.bench.conditions.Condition` of family ``name`` in ``split``."""
    spec = dict(families()[name])
    size = spec.pop("size", VGA)
    spec.pop("rim", None)
    base = get_preset("closeup_laws")
    pose = replace(base.pose, **spec.pop("pose", {}))
    preset = replace(base, name=f"{name}-{split}", lens=SPLITS[split], sizes=(size,), pose=pose, **spec)
    return Condition(f"{name}-{split}", preset, size=size, seed=seed)


def off_axis_deg(label: dict, squares: bool = False) -> np.ndarray:
    """(N,) degrees: each true corner's angle from the optical axis (board pose of the label); with
    ``squares``, each vertex of the chessboard's squares, the outer squares' outer corners included."""
    cols, rows = label["pattern_size"]
    s = float(label["square_size"])
    R = cv2.Rodrigues(np.asarray(label["rvec"], np.float64).reshape(3, 1))[0]
    c, r = np.meshgrid(np.arange(-1, cols + 1), np.arange(-1, rows + 1)) if squares else np.meshgrid(np.arange(cols), np.arange(rows))
    p = np.stack([c.ravel() * s, r.ravel() * s, np.zeros(c.size)], 1) @ R.T + np.asarray(label["tvec"], np.float64)
    return np.degrees(np.arctan2(np.hypot(p[:, 0], p[:, 1]), p[:, 2]))


def samples(cond: Condition, count: int, rim: bool | float, max_tries: int = 30):
    """Yield (index, Sample): the first ``count`` renders of ``cond`` (with ``rim`` True, only those whose outer
    squares reach ``RIM_DEG`` or more off axis; with ``rim`` a number, those whose inner corners reach that many
    degrees). Raises RuntimeError when too few pass in ``max_tries``·count."""
    from data_gen.sample import make_sample

    kept = 0
    for index in range(max_tries * max(count, 1)):
        if kept >= count:
            return
        s = make_sample(cond.preset, cond.seed, index, size=cond.size, pattern=PATTERN)
        if rim and off_axis_deg(s.label, squares=rim is True).max() < (RIM_DEG if rim is True else rim):
            continue
        kept += 1
        yield index, s
    raise RuntimeError(f"family {cond.name}: only {kept} of {count} renders passed its filter")


def run_family(name: str, split: str, seed: int, count: int, model, show: bool) -> Counter:
    """Counts of hit / wrong / miss, the misses' blamed stages and "seconds" (detection time) for one family."""
    from stage_misses import stage_figures, traced_misses

    cond = family_condition(name, split, seed)
    counts: Counter = Counter()
    found = samples(cond, count, families()[name].get("rim", False))
    for index, s, det, outcome, t in traced_misses(found, model, counts, looks=False):
        if show:
            lab = s.label
            print(f"  {cond.name} #{index}: {outcome}, {stage_figures(t, len(s.corners))} "
                  f"| {lab['distortion_model']} {2 * (lab['max_theta_deg'] or 0):.0f}° off-axis "
                  f"{off_axis_deg(lab, squares=True).max():.0f}° | {det.reason!r}", flush=True)
    return counts


def main(argv=None) -> int:
    from stage_misses import families_main

    return families_main("closeup_families", __doc__, families(), run_family, argv)


if __name__ == "__main__":
    sys.exit(main())
