"""Steeply tilted boards by family: one law of data_gen's ``tilt_steep`` pinned at a time, full boards per family.

    python benchmarks/tilt_families.py [--split tune|held-out|both] [--count 12] [--seed 301]
                                       [--families NAME,...] [--model PATH] [--show]

Each family is data_gen's ``tilt_steep`` (boards tilted 55–80° from facing the camera, squares
foreshortened to 3–4 px along the tilt, some clutter, lens blur σ 0.6 px, noise σ 1–4; 640×480 and
9×6 unless named otherwise) with one law pinned or added, the others drawn as the preset draws them:

- ``tilt-55-62``, ``tilt-62-70``, ``tilt-70-80``: the tilt (board normal against the optical axis);
- ``fill-small``: the paper's diagonal 25–45% of the image's (the preset's: 45–95%), thinner squares;
- ``dof``: depth of field along the board (data_gen ``depth_blur``: σ 0.4–0.8 px at the focus, anywhere
  along the board, growing as |1/z − 1/z_focus| to σ 1.5–3 px at its end farther from it);
- ``motion``: motion blur over 3–8 px in any direction;
- ``board-11x8``: an 11×8 board (more, smaller squares), detected as 11×8;
- ``contrast-low``: black 0.25–0.4, white 0.5–0.65 (a fifth to a third of the full swing);
- ``light``: a light gradient of 40–80% across the image and, half the time, a shadow of 30–60%;
- ``glare``: a bright sheen of 15–45% of white over 10–30% of the image's diagonal (data_gen ``glare``);
- ``jpeg``: JPEG quality 15–40;
- ``hd``: 1280×960.

The lens family is the split: ``tune`` draws the preset's lenses (pinhole, HFOV 40–90°, no or mild
distortion), the lenses the detector's steep-tilt stage was tuned on; ``held-out`` draws wide lenses,
half pinhole with strong barrel distortion (HFOV 80–120°), half full-frame equidistant fisheyes of
150–175°, the board aimed anywhere in the frame (off-centre, where the lens bends most). ``--seed``
draws other scenes (not the evaluate condition's seed-41 ones). Each image goes through
:func:`aicalib_tf.detect_corners` with the family's pattern, scored as evaluate scores it (hit: every
corner within 2 px; wrong: a full board with a corner further off). Prints one row per family (hits,
wrong, misses, the misses' blamed stage by ``stage_misses.trace``, ms per image) and the total;
``--show`` one line per miss (its tilt, square thickness, lens, the un-shear look's end).
"""

from __future__ import annotations

import sys
from collections import Counter
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from aicalib_tf.bench.conditions import PATTERN, VGA, board_tilt_deg  # noqa: E402
from data_gen.presets import Rule, get_preset  # noqa: E402

TILT = (55.0, 80.0)  # degrees: the families' tilts unless a tilt family pins another bin
SPLITS = {
    "tune": {},
    "held-out": {"lens": ("pinhole", "fisheye"), "hfov_deg": (80.0, 120.0), "distortion": ("strong",),
                 "fisheye_fov_deg": (150.0, 175.0), "fisheye_circular_from_deg": 180.0},
}


def _with(*rules: Rule) -> dict:
    return {"rules": get_preset("tilt_steep").rules + rules}


def families() -> dict[str, dict]:
    """{name: overrides of the tilt_steep preset (``pose`` as PoseConfig fields), "tilt" (lo, hi) degrees,
    "size" (width, height), "pattern" (cols, rows)}."""
    return {
        "tilt-55-62": {"tilt": (55.0, 62.0)},
        "tilt-62-70": {"tilt": (62.0, 70.0)},
        "tilt-70-80": {"tilt": (70.0, 80.0)},
        "fill-small": {"pose": {"fill": (0.25, 0.45)}},
        "dof": _with(Rule.of("depth_blur", focus=(0.0, 1.0), sigma_min=(0.4, 0.8), sigma_max=(1.5, 3.0))),
        "motion": _with(Rule.of("motion_blur", length=(3.0, 8.0))),
        "board-11x8": {"pattern": (11, 8)},
        "contrast-low": {"paper_black": (0.25, 0.4), "paper_white": (0.5, 0.65)},
        "light": _with(Rule.of("illumination_gradient", strength=(0.4, 0.8)),
                       Rule.of("shadow", 0.5, strength=(0.3, 0.6), softness=(0.5, 3.0))),
        "glare": _with(Rule.of("glare", strength=(0.15, 0.45), radius=(0.1, 0.3))),
        "jpeg": _with(Rule.of("jpeg", quality=(15, 40))),
        "hd": {"size": (1280, 960)},
    }


def family_preset(name: str, split: str):
    """(data_gen Preset, size, pattern, (lo, hi) tilt degrees) of family ``name`` in ``split``."""
    spec = dict(families()[name])
    size, pattern, tilt = spec.pop("size", VGA), spec.pop("pattern", PATTERN), spec.pop("tilt", TILT)
    base = get_preset("tilt_steep")
    pose = replace(base.pose, **{**spec.pop("pose", {}), "tilt_max_deg": tilt[1]})
    preset = replace(base, name=f"{name}-{split}", sizes=(size,), pose=pose, **{**SPLITS[split], **spec})
    return preset, size, pattern, tilt


def samples(name: str, split: str, seed: int, count: int, max_tries: int = 30):
    """Yield (index, Sample): the first ``count`` renders of the family whose board tilt is in its bin.
    Raises RuntimeError when too few pass in ``max_tries``·count."""
    from data_gen.sample import make_sample

    preset, size, pattern, (lo, hi) = family_preset(name, split)
    kept = 0
    for index in range(max_tries * max(count, 1)):
        if kept >= count:
            return
        s = make_sample(preset, seed, index, size=size, pattern=pattern)
        if not lo <= board_tilt_deg(s.label) <= hi:
            continue
        kept += 1
        yield index, s
    raise RuntimeError(f"family {name}-{split}: only {kept} of {count} renders had a tilt of {lo:g}–{hi:g}°")


def thinnest_px(corners: np.ndarray, pattern) -> float:
    """The thinnest square (px) between the true inner corners (cols·rows, 2): each square's area over its
    longest side (its height across that side; a sliver's thickness, whatever its shear)."""
    cols, rows = pattern
    c = np.asarray(corners, np.float64).reshape(rows, cols, 2)
    q = [c[:-1, :-1], c[:-1, 1:], c[1:, 1:], c[1:, :-1]]  # each square's corners in turn around it
    area = 0.5 * np.abs(sum(a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0] for a, b in zip(q, q[1:] + q[:1])))
    side = np.maximum.reduce([np.linalg.norm(b - a, axis=-1) for a, b in zip(q, q[1:] + q[:1])])
    return float((area / side).min())


def run_family(name: str, split: str, seed: int, count: int, model, show: bool) -> Counter:
    """Counts of hit / wrong / miss, the misses' blamed stages and "seconds" (detection time) for one family."""
    from stage_misses import stage_figures, traced_misses

    pattern = family_preset(name, split)[2]
    counts: Counter = Counter()
    for index, s, det, outcome, t in traced_misses(samples(name, split, seed, count), model, counts, pattern=pattern):
        counts[f"unshear: {t['unshear']}"] += 1
        if show:
            lab = s.label
            print(f"  {name}-{split} #{index}: {outcome}, {stage_figures(t, len(s.corners))} | tilt "
                  f"{board_tilt_deg(lab):.0f}° thinnest {thinnest_px(s.corners, pattern):.1f} px | "
                  f"{lab['distortion_model']} | unshear {t['unshear']} | {det.reason!r}", flush=True)
    return counts


def main(argv=None) -> int:
    from stage_misses import families_main

    return families_main("tilt_families", __doc__, families(), run_family, argv, extra=(("unshear hit", "unshear: hit"),))


if __name__ == "__main__":
    sys.exit(main())
