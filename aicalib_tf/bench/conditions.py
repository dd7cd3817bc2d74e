"""The benchmark's named test conditions and severity sweeps, as data_gen presets with fixed seeds.

Every condition is a :class:`Condition`: a frozen data_gen :class:`~data_gen.presets.Preset`
(built from the library's presets with overrides), an image size, a seed, and for sweeps the
sweep's name and the level's nominal severity. Images are ``make_sample(preset, seed, index)``
for the first indices that pass the condition's filter, so every run renders the same images.
Sweep levels of one sweep share their seed, so the same scenes (camera, board, pose) are shown
at every level of noise, blur, contrast or JPEG quality: the curves compare like with like.

No TensorFlow here: conditions are pure data_gen.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import cv2
import numpy as np

from data_gen.pose import PoseConfig
from data_gen.presets import Preset, Rule, get_preset
from data_gen.sample import Sample, make_sample

__all__ = [
    "PATTERN", "is_fisheye", "Condition", "named_conditions", "sweep_conditions", "all_conditions", "select_conditions",
    "condition_samples", "calibration_sequences", "board_tilt_deg", "square_px", "CALIB_SEED", "CALIB_CAMERAS",
    "FISHEYE_SEQUENCES", "fisheye_preset", "generalize_conditions",
]

PATTERN = (9, 6)
VGA = (640, 480)
HD = (1920, 1080)
CALIB_SEED = 11  # cameras 0, 1 get mild lenses (k1 -0.03, +0.03), cameras 2, 3 strong barrel (k1 -0.33, -0.31)
CALIB_CAMERAS = (0, 1, 2, 3)
# Fisheye calibration sequences (data_gen ``calib_fisheye``, 1280×960, noise σ 2, seed CALIB_SEED):
# name -> (full field of view in degrees, camera id). 185°: circular image, the circle inside the frame.
FISHEYE_SEQUENCES = {"fisheye185": (185.0, 100), "fisheye150": (150.0, 101)}

_OPTICS = Rule.of("gaussian_blur", sigma=0.6)  # the mild blur of every real lens, as data_gen's presets
_READ_NOISE = Rule.of("gaussian_noise", sigma=2.0)
# Low contrast "black 100 / white 150": contrast() maps v -> mid + f·(v − mid); f = 50/255 and
# mid = 100/205 send 0 -> 100/255 and 1 -> 150/255 (paper grey levels then fall inside that range).
CONTRAST_FACTOR = 50.0 / 255.0
CONTRAST_MID = 100.0 / 205.0


@dataclass(frozen=True)
class Condition:
    """One set of benchmark images.

    name : unique, e.g. ``"noise40"`` or ``"sweep-noise-40"``.
    preset : the data_gen recipe. size : (width, height) px. seed : data_gen seed.
    has_board : False for board-free images (false positives are counted there).
    sweep : sweep name (``"noise"``, ``"blur"``, …) or None for a named condition.
    level : the level's nominal severity (σ grey levels, σ px, contrast factor, JPEG quality,
        k1 class, tilt band top in degrees); NaN for named conditions.
    min_tilt_deg : keep only images whose board tilt (normal vs optical axis) is at least this.
    description : one line for the report.
    """

    name: str
    preset: Preset
    size: tuple[int, int] = VGA
    seed: int = 21
    has_board: bool = True
    sweep: str | None = None
    level: float = float("nan")
    min_tilt_deg: float = 0.0
    description: str = ""


def _clean_with(rules: tuple[Rule, ...], name: str, **overrides) -> Preset:
    return replace(get_preset("clean"), name=name, rules=rules, **overrides)


def fisheye_preset(fov_deg: float, base: str = "fisheye", **overrides) -> Preset:
    """data_gen's ``base`` fisheye preset with one fixed field of view (degrees) and no partial boards.

    The name becomes ``f"{base}{fov:g}"``; ``overrides`` replace further fields.
    """
    fields = dict(name=f"{base}{fov_deg:g}", fisheye_fov_deg=(fov_deg, fov_deg), partial_probability=0.0)
    if base == "fisheye":
        fields.update(sizes=(VGA,), clutter=(0.0, 0.5))
    return replace(get_preset(base), **{**fields, **overrides})


def is_fisheye(preset: Preset) -> bool:
    """True when the preset's cameras are fisheyes (equidistant, ds, eucm, or a mix of them)."""
    lenses = (preset.lens,) if isinstance(preset.lens, str) else tuple(preset.lens)
    return all(ln != "pinhole" for ln in lenses)


def named_conditions() -> list[Condition]:
    """The detection issue's conditions at 640×480 (plus one 1920×1080 set), 9×6 boards."""
    wide = dict(hfov_deg=(90.0, 120.0), distortion=("strong",))
    c = [
        Condition("clean", get_preset("clean"), description="sharp, well lit, lens blur σ 0.6 px"),
        Condition("noise20", _clean_with((_OPTICS, Rule.of("gaussian_noise", sigma=20.0)), "noise20"),
                  description="Gaussian noise σ 20 grey levels"),
        Condition("noise40", _clean_with((_OPTICS, Rule.of("gaussian_noise", sigma=40.0)), "noise40"),
                  description="Gaussian noise σ 40 grey levels"),
        Condition("blur2", _clean_with((Rule.of("gaussian_blur", sigma=2.0), _READ_NOISE), "blur2"),
                  description="Gaussian blur σ 2 px"),
        Condition("blur3", _clean_with((Rule.of("gaussian_blur", sigma=3.0), _READ_NOISE), "blur3"),
                  description="Gaussian blur σ 3 px"),
        Condition("contrast", _clean_with((Rule.of("contrast", factor=CONTRAST_FACTOR, mid=CONTRAST_MID), _OPTICS,
                                           _READ_NOISE), "contrast"),
                  description="low contrast: black 100 / white 150 grey levels, noise σ 2"),
        Condition("shading", _clean_with((Rule.of("illumination_gradient", strength=0.7),
                                          Rule.of("shadow", strength=0.6, softness=(0.5, 3.0)), _OPTICS, _READ_NOISE),
                                         "shading"),
                  description="strong illumination gradient (70 %) and a hard shadow (60 %)"),
        Condition("jpeg15", _clean_with((_OPTICS, _READ_NOISE, Rule.of("jpeg", quality=15)), "jpeg15"),
                  description="JPEG quality 15"),
        Condition("saltpepper5", _clean_with((_OPTICS, Rule.of("salt_pepper", fraction=0.05)), "saltpepper5"),
                  description="5 % salt-and-pepper pixels"),
        Condition("barrel", _clean_with((_OPTICS, _READ_NOISE), "barrel", **wide),
                  description="wide lens (HFOV 90–120°), strong barrel k1 −0.45…−0.25"),
        Condition("fisheye150", fisheye_preset(150.0), description="full-frame fisheye, 150° diagonal (equidistant)"),
        Condition("fisheye185", fisheye_preset(185.0),
                  description="circular fisheye, 185°: the image circle inside the frame, dark outside it"),
        Condition("fisheye_closeup", replace(get_preset("fisheye_closeup"), sizes=(VGA,)),
                  description="close-up boards through circular 150–200° fisheyes (equidistant, DS, EUCM): "
                              "the paper spans 40–90% of the image circle, vignetting to black at the rim, "
                              "blur growing towards it"),
        Condition("tilt60", _clean_with((_OPTICS, _READ_NOISE), "tilt60", pose=PoseConfig(tilt_max_deg=62.0, fill=(0.4, 0.9))),
                  min_tilt_deg=50.0, description="steep tilt: 50–62° between board normal and optical axis"),
        Condition("small", _clean_with((_OPTICS, _READ_NOISE), "small", pose=PoseConfig(tilt_max_deg=30.0, fill=(0.12, 0.16))),
                  description="small boards: squares about 8 px"),
        Condition("occluded", get_preset("occluded"), description="objects hide 8–30 % of the board"),
        Condition("partial", get_preset("partial"), description="board partly out of frame (30–99 % of corners in)"),
        Condition("clutter", get_preset("clutter"), has_board=False,
                  description="board-free: clutter, text and checker-like patches"),
        Condition("hd1080", get_preset("clean"), size=HD, description="clean, 1920×1080"),
    ]
    return c


def sweep_conditions() -> list[Condition]:
    """Severity sweeps, each level on the same scenes (seed 31): noise, blur, contrast, JPEG, k1, tilt."""
    seed = 31
    out = []
    for s in (0, 10, 20, 30, 40, 50, 60):
        out.append(Condition(f"sweep-noise-{s}", _clean_with((_OPTICS, Rule.of("gaussian_noise", sigma=float(s))), f"noise{s}"),
                             seed=seed, sweep="noise", level=float(s), description=f"Gaussian noise σ {s}"))
    for s in (0.5, 1.0, 2.0, 3.0, 4.0):
        out.append(Condition(f"sweep-blur-{s:g}", _clean_with((Rule.of("gaussian_blur", sigma=s), _READ_NOISE), f"blur{s:g}"),
                             seed=seed, sweep="blur", level=s, description=f"Gaussian blur σ {s:g} px"))
    for f in (1.0, 0.5, 0.3, 0.2, 0.1, 0.05):
        out.append(Condition(f"sweep-contrast-{f:g}",
                             _clean_with((Rule.of("contrast", factor=f), _OPTICS, _READ_NOISE), f"contrast{f:g}"),
                             seed=seed, sweep="contrast", level=f,
                             description=f"contrast ×{f:g} (black–white span {255 * f:.0f} grey levels), noise σ 2"))
    for q in (90, 50, 30, 15, 8, 4):
        out.append(Condition(f"sweep-jpeg-{q}", _clean_with((_OPTICS, _READ_NOISE, Rule.of("jpeg", quality=q)), f"jpeg{q}"),
                             seed=seed, sweep="jpeg", level=float(q), description=f"JPEG quality {q}"))
    for k, (level, lens) in enumerate((("none", 0.0), ("mild", -0.05), ("strong", -0.35))):
        out.append(Condition(f"sweep-distortion-{level}",
                             _clean_with((_OPTICS, _READ_NOISE), f"distortion-{level}", hfov_deg=(80.0, 110.0),
                                         distortion=(level,)),
                             seed=seed, sweep="distortion", level=lens,
                             description=f"{level} lens distortion, HFOV 80–110° (level: typical k1)"))
    for lo, hi in ((0, 15), (15, 30), (30, 45), (45, 55), (55, 65)):
        out.append(Condition(f"sweep-tilt-{hi}",
                             _clean_with((_OPTICS, _READ_NOISE), f"tilt{hi}", pose=PoseConfig(tilt_max_deg=float(hi), fill=(0.4, 0.9))),
                             seed=seed, sweep="tilt", level=float(hi), min_tilt_deg=float(lo),
                             description=f"board tilt {lo}–{hi}°"))
    return out


def generalize_conditions() -> list[Condition]:
    """Conditions the detector was not tuned on (seed 41, 640×480): data_gen's ``closeup_laws`` split by
    lens family (``closeup-eq``: equidistant; ``closeup-unified``: DS and EUCM, the held-out family)
    and ``tilt_steep`` kept at 55–80°. Not in ``all``: select them by name or as ``generalize``."""
    laws = replace(get_preset("closeup_laws"), sizes=(VGA,))
    return [
        Condition("closeup-eq", replace(laws, name="closeup-eq", lens="fisheye"), seed=41,
                  description="close-ups, equidistant 150–210° circles, cos⁴/polynomial/hard rim, field blur"),
        Condition("closeup-unified", replace(laws, name="closeup-unified", lens=("ds", "eucm")), seed=41,
                  description="close-ups, DS and EUCM 150–210° circles, cos⁴/polynomial/hard rim, field blur"),
        Condition("tilt-steep", get_preset("tilt_steep"), seed=41, min_tilt_deg=55.0,
                  description="steep tilt: 55–80° between board normal and optical axis"),
    ]


def all_conditions() -> list[Condition]:
    """The named conditions followed by every sweep level."""
    return named_conditions() + sweep_conditions()


def select_conditions(spec: str | None) -> list[Condition]:
    """Conditions named in a comma list; a sweep name (``noise``) selects all its levels.

    None or ``"all"``: everything. ``"named"`` / ``"sweeps"``: one group. Unknown names raise ValueError.
    """
    everything = all_conditions()
    if spec is None or spec.strip() in ("", "all"):
        return everything
    chosen: list[Condition] = []
    sweeps = {c.sweep for c in everything if c.sweep}
    for item in (s.strip() for s in spec.split(",") if s.strip()):
        if item == "named":
            picked = named_conditions()
        elif item == "generalize":
            picked = generalize_conditions()
        elif item == "sweeps":
            picked = sweep_conditions()
        elif item in sweeps:
            picked = [c for c in everything if c.sweep == item]
        else:
            picked = [c for c in everything + generalize_conditions() if c.name == item]
            if not picked:
                names = ", ".join([c.name for c in named_conditions() + generalize_conditions()] + sorted(sweeps)
                                  + ["named", "sweeps", "generalize", "all"])
                raise ValueError(f"unknown condition {item!r}; choose from: {names}")
        chosen += [c for c in picked if c not in chosen]
    return chosen


def board_tilt_deg(label: dict) -> float:
    """Angle (degrees) between the board's normal and the optical axis; NaN without a board."""
    if label.get("rvec") is None:
        return float("nan")
    R, _ = cv2.Rodrigues(np.asarray(label["rvec"], dtype=np.float64).reshape(3, 1))
    return float(math.degrees(math.acos(min(1.0, abs(R[2, 2])))))


def square_px(label: dict) -> float:
    """Median distance (px) between neighbouring inner corners: the apparent square size; NaN without a board."""
    if not label.get("corners"):
        return float("nan")
    cols, rows = label["pattern_size"]
    c = np.asarray(label["corners"], dtype=np.float64).reshape(rows, cols, 2)
    d = np.r_[np.linalg.norm(np.diff(c, axis=1), axis=2).ravel(), np.linalg.norm(np.diff(c, axis=0), axis=2).ravel()]
    return float(np.median(d))


def condition_samples(cond: Condition, count: int, *, max_tries: int = 20):
    """Yield ``(index, Sample)`` for the first ``count`` images of ``cond`` that pass its filter.

    Renders up to ``max_tries · count`` candidates (the tilt filter rejects some); raises
    RuntimeError if too few pass.
    """
    if count < 0:
        raise ValueError(f"count must be >= 0, got {count}")
    kept = 0
    for index in range(max_tries * max(count, 1)):
        if kept >= count:
            return
        s = make_sample(cond.preset, cond.seed, index, size=cond.size, pattern=PATTERN)
        if cond.min_tilt_deg > 0 and not board_tilt_deg(s.label) >= cond.min_tilt_deg:
            continue
        kept += 1
        yield index, s
    if kept < count:
        raise RuntimeError(f"condition {cond.name}: only {kept} of {count} images passed its filter")


def calibration_sequences(views: int, cameras=CALIB_CAMERAS, seed: int = CALIB_SEED, *,
                          fisheye: tuple[str, ...] = ()) -> list[tuple[int, list[Sample]]]:
    """The calibration sequences with their truth: ``[(camera_id, [Sample] * views)]``.

    views : 3–20 views per camera (the first ones of each 20-view sequence).
    cameras : data_gen ``calib`` cameras (640×480; 0, 1 mild lenses, 2, 3 strong barrel).
    fisheye : names from :data:`FISHEYE_SEQUENCES` to add (``calib_fisheye``, 1280×960, σ 2).
    """
    if not 3 <= views <= 20:
        raise ValueError(f"views per calibration sequence must be 3..20, got {views}")
    unknown = [f for f in fisheye if f not in FISHEYE_SEQUENCES]
    if unknown:
        raise ValueError(f"unknown fisheye sequence(s) {unknown}; choose from {sorted(FISHEYE_SEQUENCES)}")
    n = get_preset("calib").views_per_camera
    out = [(cam, [make_sample("calib", seed, cam * n + v) for v in range(views)]) for cam in cameras]
    for name in fisheye:
        fov, cam = FISHEYE_SEQUENCES[name]
        preset = fisheye_preset(fov, "calib_fisheye")
        out.append((cam, [make_sample(preset, seed, cam * n + v) for v in range(views)]))
    return out
