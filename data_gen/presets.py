"""Named scene recipes: which cameras, boards, poses, clutter and degradations to draw.

A :class:`Preset` is a frozen description; :func:`data_gen.sample.make_sample` turns a preset,
a seed and an image index into one image with its labels. Degradation rules name a function of
:mod:`data_gen.degrade` and give each parameter as a fixed value or a ``(lo, hi)`` uniform range.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, replace

from .pose import PoseConfig

__all__ = ["Rule", "Preset", "PRESETS", "get_preset", "COMMON_SIZES", "LENSES"]

COMMON_SIZES = ((640, 480), (800, 600), (1024, 768), (1280, 720), (1280, 960), (1920, 1080))
INT_PARAMS = {"quality"}
LENSES = ("pinhole", "fisheye", "ds", "eucm")


@dataclass(frozen=True)
class Rule:
    """Apply degradation ``name`` with probability ``p``; ``params`` maps name -> value | (lo, hi)."""

    name: str
    p: float = 1.0
    params: tuple[tuple[str, object], ...] = ()

    @staticmethod
    def of(name: str, p: float = 1.0, **params) -> "Rule":
        return Rule(name, p, tuple(sorted(params.items())))


@dataclass(frozen=True)
class Preset:
    """A scene recipe. Ranges are ``(lo, hi)``, drawn uniformly.

    lens : "pinhole" (OpenCV's 5 coefficients; ``hfov_deg`` and ``distortion`` apply) or
    "fisheye" (equidistant Kannala–Brandt with full FOV from ``fisheye_fov_deg``, see
    :func:`data_gen.camera.sample_fisheye`), "ds" or "eucm" (Double Sphere or Extended Unified
    with full FOV from ``fisheye_fov_deg``, :func:`data_gen.camera.sample_unified_fisheye`), or a
    tuple of these names, one drawn per camera. ``fisheye_circular_from_deg``: fisheyes of at least
    this FOV are circular (the whole image circle inside the frame), narrower ones full frame.
    board : None (chessboards, sized by ``pattern`` or the ranges), a ChArUco description,
    ``charuco:11x8,square=30mm,marker=22mm,dict=DICT_5X5_100`` (:mod:`aicalib_tf.geometry.charuco`), or an
    AprilGrid, ``aprilgrid:6x6,tag=88mm,spacing=0.3`` or a Kalibr target YAML (:mod:`data_gen.targets`).
    margin_range : the chessboard paper's white margin around the outer squares, in squares.
    paper_black, paper_white : the ranges of the chessboard's black and white reflectance (0..1).
    flex : (w_x, w_y) every chessboard's parabolic sag in squares (:class:`data_gen.board.Board`'s ``flex``,
    recorded in the label's ``board``); (0, 0): flat boards. shape : every chessboard's shape terms in squares
    (:class:`data_gen.board.Board`'s ``shape``, :mod:`aicalib_tf.geometry.board_shape`); (): none.
    antialias : the board's edges area-sampled (:func:`data_gen.render.render_board`); False: one sample at each
    pixel's centre (edges step by whole pixels, as a renderer without supersampling draws them).
    """

    name: str
    description: str
    sizes: tuple[tuple[int, int], ...] = ((640, 480),)
    hfov_deg: tuple[float, float] = (40.0, 90.0)
    distortion: tuple[str, ...] = ("none", "mild")
    pattern: tuple[int, int] | None = None
    cols_range: tuple[int, int] = (3, 12)
    rows_range: tuple[int, int] = (3, 9)
    pose: PoseConfig = field(default_factory=PoseConfig)
    partial_probability: float = 0.0
    board_probability: float = 1.0
    clutter: tuple[float, float] = (0.0, 1.0)
    checker_distractors: tuple[float, float] = (0.0, 0.0)
    occlusion_probability: float = 0.0
    occlusion_severity: tuple[float, float] = (0.1, 0.3)
    rules: tuple[Rule, ...] = ()
    views_per_camera: int = 1
    lens: str | tuple[str, ...] = "pinhole"
    fisheye_fov_deg: tuple[float, float] = (150.0, 200.0)
    board: str | None = None
    fisheye_circular_from_deg: float = 175.0
    flex: tuple[float, float] = (0.0, 0.0)
    shape: tuple[float, ...] = ()
    antialias: bool = True
    margin_range: tuple[float, float] = (0.15, 1.0)
    paper_black: tuple[float, float] = (0.04, 0.22)
    paper_white: tuple[float, float] = (0.7, 0.95)

    def __post_init__(self):
        if (any(self.flex) or any(self.shape)) and self.board is not None:
            raise ValueError(f"preset {self.name!r}: flex and shape apply to chessboards only, not {self.board!r}")
        lenses = (self.lens,) if isinstance(self.lens, str) else tuple(self.lens)
        if not lenses or any(ln not in LENSES for ln in lenses):
            raise ValueError(f"preset {self.name!r}: lens must be one of {LENSES} or a tuple of them, got {self.lens!r}")
        if self.board is not None:
            from .targets import parse_marker_board

            parse_marker_board(self.board)  # a bad description fails here, before anything is drawn

    def to_dict(self) -> dict:
        return asdict(self)


_OPTICS = Rule.of("gaussian_blur", sigma=0.6)  # every real lens blurs a little

PRESETS: dict[str, Preset] = {}


def _add(p: Preset) -> None:
    PRESETS[p.name] = p


_add(Preset(
    name="clean",
    description="Sharp, well-lit boards fully in frame; only the mild blur of a real lens (σ=0.6 px).",
    pose=PoseConfig(tilt_max_deg=45.0, fill=(0.3, 0.8)),
    clutter=(0.0, 0.5),
    rules=(_OPTICS,),
))
_add(Preset(
    name="noisy",
    description="Sensor noise: Gaussian σ 5–40 grey levels, often with photon shot noise.",
    pose=PoseConfig(tilt_max_deg=45.0, fill=(0.3, 0.8)),
    rules=(_OPTICS, Rule.of("shot_noise", 0.5, photons=(100.0, 2000.0)), Rule.of("gaussian_noise", sigma=(5.0, 40.0))),
))
_add(Preset(
    name="blur",
    description="Optical blur σ 0.6–3.5 px, with motion blur and defocus.",
    pose=PoseConfig(tilt_max_deg=45.0, fill=(0.3, 0.8)),
    rules=(
        Rule.of("gaussian_blur", sigma=(0.6, 3.5)),
        Rule.of("motion_blur", 0.35, length=(3.0, 12.0)),
        Rule.of("defocus", 0.35, radius=(1.5, 4.0)),
        Rule.of("gaussian_noise", sigma=2.0),
    ),
))
_add(Preset(
    name="distorted",
    description="Wide-angle lenses (HFOV 70–120°) with strong barrel (k1 to -0.45) or pincushion distortion.",
    hfov_deg=(70.0, 120.0),
    distortion=("strong", "strong", "pincushion"),
    pose=PoseConfig(tilt_max_deg=60.0, fill=(0.3, 0.9)),
    rules=(_OPTICS, Rule.of("gaussian_noise", sigma=2.0)),
))
_add(Preset(
    name="occluded",
    description="Objects in front of the board hide some corners (flagged invisible).",
    pose=PoseConfig(tilt_max_deg=45.0, fill=(0.35, 0.8)),
    occlusion_probability=1.0,
    occlusion_severity=(0.08, 0.3),
    rules=(_OPTICS, Rule.of("gaussian_noise", sigma=2.0)),
))
_add(Preset(
    name="partial",
    description="Boards partly out of frame: some inner corners fall outside the image.",
    pose=PoseConfig(tilt_max_deg=45.0, fill=(0.4, 1.0), framing="partial"),
    partial_probability=1.0,
    rules=(_OPTICS, Rule.of("gaussian_noise", sigma=2.0)),
))
_add(Preset(
    name="clutter",
    description="Board-free images: clutter, text and checker-like patches that are not a board.",
    board_probability=0.0,
    clutter=(1.0, 4.0),
    checker_distractors=(1.0, 4.0),
    rules=(_OPTICS, Rule.of("gaussian_noise", 0.5, sigma=(2.0, 20.0))),
))

_HARD_RULES = (
    Rule.of("illumination_gradient", 0.4, strength=(0.2, 0.7)),
    Rule.of("vignetting", 0.3, strength=(0.2, 0.6)),
    Rule.of("shadow", 0.3, strength=(0.3, 0.7), softness=(0.5, 3.0)),
    Rule.of("contrast", 0.3, factor=(0.2, 0.6)),
    Rule.of("exposure", 0.3, gain=(0.3, 2.2)),
    Rule.of("gaussian_blur", sigma=(0.6, 3.0)),
    Rule.of("motion_blur", 0.2, length=(3.0, 10.0)),
    Rule.of("defocus", 0.2, radius=(1.5, 3.5)),
    Rule.of("shot_noise", 0.4, photons=(50.0, 1000.0)),
    Rule.of("gaussian_noise", sigma=(5.0, 50.0)),
    Rule.of("jpeg", 0.4, quality=(8, 60)),
    Rule.of("salt_pepper", 0.25, fraction=(0.005, 0.06)),
)
_add(Preset(
    name="hard",
    description="Everything at once: wide lenses, steep tilt, clutter, occlusion, partial views, heavy degradations.",
    sizes=COMMON_SIZES,
    hfov_deg=(40.0, 120.0),
    distortion=("none", "mild", "strong", "pincushion"),
    pose=PoseConfig(tilt_max_deg=60.0, fill=(0.2, 0.9)),
    partial_probability=0.25,
    clutter=(1.0, 4.0),
    checker_distractors=(0.5, 3.0),
    occlusion_probability=0.3,
    rules=_HARD_RULES,
))
_add(Preset(
    name="train",
    description="A broad mix for training the corner CNN: clean to hard, all patterns, lenses and degradations.",
    hfov_deg=(40.0, 120.0),
    distortion=("none", "mild", "mild", "strong", "pincushion"),
    cols_range=(3, 20),
    rows_range=(3, 15),
    pose=PoseConfig(tilt_max_deg=60.0, fill=(0.2, 0.95)),
    partial_probability=0.25,
    clutter=(0.0, 4.0),
    checker_distractors=(0.0, 3.0),
    occlusion_probability=0.2,
    rules=(
        Rule.of("illumination_gradient", 0.25, strength=(0.1, 0.7)),
        Rule.of("vignetting", 0.2, strength=(0.1, 0.6)),
        Rule.of("shadow", 0.15, strength=(0.2, 0.7), softness=(0.5, 3.0)),
        Rule.of("contrast", 0.2, factor=(0.15, 0.8)),
        Rule.of("exposure", 0.2, gain=(0.3, 2.2)),
        Rule.of("gaussian_blur", sigma=(0.4, 3.0)),
        Rule.of("motion_blur", 0.15, length=(2.0, 10.0)),
        Rule.of("defocus", 0.15, radius=(1.0, 3.5)),
        Rule.of("shot_noise", 0.3, photons=(50.0, 2000.0)),
        Rule.of("gaussian_noise", 0.8, sigma=(1.0, 50.0)),
        Rule.of("jpeg", 0.25, quality=(8, 80)),
        Rule.of("salt_pepper", 0.15, fraction=(0.002, 0.06)),
    ),
))
_add(Preset(
    name="calib",
    description="Calibration sequences: 20 views per camera (mild or strong barrel), noise σ=10.",
    hfov_deg=(50.0, 110.0),
    distortion=("mild", "strong"),
    pattern=(9, 6),
    pose=PoseConfig(tilt_max_deg=50.0, fill=(0.3, 0.8)),
    rules=(_OPTICS, Rule.of("gaussian_noise", sigma=10.0)),
    views_per_camera=20,
))
_add(Preset(
    name="fisheye",
    description="Fisheye lenses (equidistant, 150–200° diagonal; circular images from 175°), boards up to the rim.",
    sizes=((640, 480), (1280, 960)),
    lens="fisheye",
    fisheye_fov_deg=(150.0, 200.0),
    pose=PoseConfig(tilt_max_deg=50.0, fill=(0.2, 0.6)),
    partial_probability=0.15,
    clutter=(0.0, 1.0),
    rules=(_OPTICS, Rule.of("gaussian_noise", sigma=2.0)),
))
_add(Preset(
    name="calib_fisheye",
    description="Fisheye calibration sequences: 20 views per camera, 150–200° lenses, 1280×960, noise σ=2.",
    sizes=((1280, 960),),
    lens="fisheye",
    fisheye_fov_deg=(150.0, 200.0),
    pattern=(9, 6),
    pose=PoseConfig(tilt_max_deg=50.0, fill=(0.25, 0.6)),
    rules=(_OPTICS, Rule.of("gaussian_noise", sigma=2.0)),
    views_per_camera=20,
))
_CLOSEUP_LENSES = ("fisheye", "fisheye", "ds", "eucm")  # half equidistant (Kannala–Brandt), half unified
_add(Preset(
    name="fisheye_closeup",
    description="Close-up boards through circular 150–200° fisheyes (equidistant, DS, EUCM): the paper spans "
                "40–90% of the image circle, up to its rim, lines bend strongly; vignetting falls to black at "
                "the circle and the blur grows towards it (shallow focus).",
    sizes=((640, 480), (1280, 960)),
    lens=_CLOSEUP_LENSES,
    fisheye_fov_deg=(150.0, 200.0),
    fisheye_circular_from_deg=0.0,
    pose=PoseConfig(tilt_max_deg=45.0, circle_fill=(0.4, 0.9), max_view_angle_deg=85.0),
    clutter=(0.0, 1.0),
    rules=(
        Rule.of("circle_falloff", strength=(0.85, 1.0), power=(2.0, 5.0)),
        Rule.of("field_blur", sigma_centre=(0.5, 0.9), sigma_rim=(1.2, 2.5), power=(1.5, 3.0)),
        Rule.of("gaussian_noise", sigma=2.0),
    ),
))
_add(Preset(
    name="closeup_laws",
    description="Close-up boards through circular 150–210° fisheyes (equidistant, DS, EUCM) under other laws "
                "than fisheye_closeup's: the paper spans 30–90% of the image circle and reaches its rim, light "
                "falls by a cos⁴, a polynomial or a hard black-rim law, blur grows linearly to quadratically "
                "towards the rim (to σ 3.5 px), narrow margins, lower contrast, small checker patterns in clutter.",
    sizes=((640, 480), (1280, 960)),
    lens=("fisheye", "ds", "eucm"),
    fisheye_fov_deg=(150.0, 210.0),
    fisheye_circular_from_deg=0.0,
    pose=PoseConfig(tilt_max_deg=50.0, circle_fill=(0.3, 0.9), max_view_angle_deg=88.0),
    clutter=(0.5, 2.0),
    checker_distractors=(1.0, 3.0),
    margin_range=(0.05, 1.0),
    paper_black=(0.04, 0.4),
    paper_white=(0.55, 0.95),
    rules=(
        Rule.of("rim_vignetting", law=("cos4", "poly", "hard"), strength=(0.9, 1.0), edge=(0.6, 0.9)),
        Rule.of("field_blur", sigma_centre=(0.4, 1.0), sigma_rim=(1.0, 3.5), power=(1.0, 2.0)),
        Rule.of("gaussian_noise", sigma=(1.0, 6.0)),
    ),
))
_add(Preset(
    name="tilt_steep",
    description="Boards tilted up to 80° from facing the camera (squares foreshortened to 3–4 px along the "
                "tilt), pinhole lenses with no or mild distortion, some clutter.",
    hfov_deg=(40.0, 90.0),
    pose=PoseConfig(tilt_max_deg=80.0, fill=(0.45, 0.95), max_view_angle_deg=88.0),
    clutter=(0.0, 1.0),
    checker_distractors=(0.0, 1.0),
    rules=(_OPTICS, Rule.of("gaussian_noise", sigma=(1.0, 4.0))),
))


_RIM_LAWS = (  # domain randomisation of the light and blur laws across the field
    Rule.of("circle_falloff", 0.3, strength=(0.5, 1.0), power=(1.5, 5.0)),
    Rule.of("rim_vignetting", 0.45, law=("cos4", "poly", "hard"), strength=(0.4, 1.0), edge=(0.5, 0.95)),
    Rule.of("field_blur", 0.7, sigma_centre=(0.4, 1.2), sigma_rim=(0.8, 4.0), power=(0.8, 3.0)),
)
# image laws whose families the corner map misses (benchmarks/closeup_families.py noise-poisson, sharpen)
_MAP_GAPS = (
    Rule.of("shot_noise", 0.1, photons=(20.0, 100.0)),  # low light: 20-100 photons at white
    Rule.of("unsharp", 0.1, amount=(0.3, 1.5), sigma=(0.8, 2.0)),
)
_OTHER_CAMERAS = (  # image formation of other cameras and renderers (data_gen.sensor), each at 10%
    Rule.of("circle_edge", 0.1, black_at=1.0, width=(0.02, 0.1)),
    Rule.of("field_defocus", 0.1, radius_centre=(0.5, 1.5), radius_rim=(1.5, 5.0), power=(1.0, 2.0)),
    Rule.of("astigmatism", 0.1, sigma_radial=(1.0, 4.0), sigma_tangential=(0.0, 1.5), power=(1.5, 3.0)),
    Rule.of("lateral_ca", 0.1, shift=(0.5, 2.5), power=(1.0, 2.0)),
    Rule.of("bayer_demosaic", 0.1, gain_r=(0.4, 0.8), gain_b=(0.5, 0.9), method=("bilinear", "edge")),
    Rule.of("tone_curve", 0.1, law=("srgb", "gamma"), gamma=(1.8, 2.4)),
)
_add(Preset(
    name="train_fisheye",
    description="Training mix of equidistant fisheyes only (120–210°, most of them circular): boards from far to "
                "close-up, 30–95% of the image circle and up to its rim, tilts to 65°; vignetting, rim "
                "fall-off and field blur under randomised laws, low contrast, noise, JPEG; at 10% low-light "
                "photon noise and an image processor's sharpening.",
    lens="fisheye",
    fisheye_fov_deg=(120.0, 210.0),
    fisheye_circular_from_deg=150.0,
    cols_range=(3, 14),
    rows_range=(3, 10),
    pose=PoseConfig(tilt_max_deg=65.0, circle_fill=(0.3, 0.95), max_view_angle_deg=88.0),
    clutter=(0.0, 2.0),
    margin_range=(0.05, 1.0),
    paper_black=(0.04, 0.4),
    paper_white=(0.55, 0.95),
    rules=_RIM_LAWS + (
        Rule.of("gaussian_blur", 0.3, sigma=(0.4, 1.5)),
        Rule.of("contrast", 0.3, factor=(0.3, 0.9)),
        Rule.of("shot_noise", 0.2, photons=(100.0, 2000.0)),
        Rule.of("gaussian_noise", 0.9, sigma=(1.0, 25.0)),
        Rule.of("jpeg", 0.15, quality=(20, 80)),
    ) + _MAP_GAPS,
))
_add(Preset(
    name="train_rim",
    description="Training mix of close-ups on the rim of circular equidistant fisheyes (180–210°): most boards "
                "aimed at the image circle's rim and past it (the circle may cut the paper), their outer corners "
                "80–100° off axis, squeezed and darkened; train_fisheye's laws plus other cameras' and renderers' "
                "image laws (disc defocus, astigmatism, lateral CA, mosaic, sRGB, sharpening, soft rim) at 10%.",
    lens="fisheye",
    fisheye_fov_deg=(180.0, 210.0),
    fisheye_circular_from_deg=0.0,
    cols_range=(3, 14),
    rows_range=(3, 10),
    pose=PoseConfig(tilt_max_deg=50.0, framing="any", min_visible_fraction=0.6, circle_fill=(0.3, 0.9),
                    max_view_angle_deg=88.0, rim_share=0.9, rim_reach=(1.0, 1.3)),
    clutter=(0.5, 2.0),
    checker_distractors=(0.0, 2.0),
    margin_range=(0.0, 1.0),
    paper_black=(0.04, 0.4),
    paper_white=(0.55, 0.95),
    rules=_RIM_LAWS + (
        Rule.of("contrast", 0.3, factor=(0.3, 0.9)),
        Rule.of("shot_noise", 0.2, photons=(100.0, 2000.0)),
        Rule.of("gaussian_noise", 0.9, sigma=(1.0, 25.0)),
        Rule.of("jpeg", 0.15, quality=(20, 80)),
    ) + _MAP_GAPS + _OTHER_CAMERAS,
))
_add(Preset(
    name="train_steep",
    description="Training mix of steeply tilted boards (up to 80°, squares foreshortened to a few px) through "
                "pinhole lenses with every distortion, partly out of frame at times; the train preset's "
                "degradations plus randomised vignetting and field-blur laws.",
    hfov_deg=(40.0, 120.0),
    distortion=("none", "mild", "mild", "strong", "pincushion"),
    cols_range=(3, 16),
    rows_range=(3, 12),
    pose=PoseConfig(tilt_max_deg=80.0, fill=(0.3, 0.95), max_view_angle_deg=88.0),
    partial_probability=0.2,
    clutter=(0.0, 3.0),
    margin_range=(0.05, 1.0),
    rules=(
        Rule.of("rim_vignetting", 0.2, law=("cos4", "poly"), strength=(0.3, 0.9), edge=(0.7, 1.0)),
        Rule.of("field_blur", 0.2, sigma_centre=(0.4, 1.0), sigma_rim=(0.8, 2.5), power=(1.0, 2.0)),
        Rule.of("contrast", 0.2, factor=(0.2, 0.8)),
        Rule.of("gaussian_blur", sigma=(0.4, 2.0)),
        Rule.of("motion_blur", 0.1, length=(2.0, 6.0)),
        Rule.of("shot_noise", 0.2, photons=(100.0, 2000.0)),
        Rule.of("gaussian_noise", 0.8, sigma=(1.0, 30.0)),
        Rule.of("jpeg", 0.15, quality=(20, 80)),
    ),
))


def get_preset(name: str | Preset, **overrides) -> Preset:
    """Look up a preset by name (or pass one through), optionally with fields replaced."""
    if isinstance(name, Preset):
        preset = name
    else:
        try:
            preset = PRESETS[name]
        except KeyError:
            raise ValueError(f"unknown preset {name!r}; choose from: {', '.join(PRESETS)}") from None
    return replace(preset, **overrides) if overrides else preset
