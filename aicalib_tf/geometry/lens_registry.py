"""The lens-model registry: every model's name to its implementation (:class:`~aicalib_tf.geometry.lens_model.LensModel`).

A new model is one module beside the others and one entry in :data:`REGISTRY`; the renderer, the
fit, the model choice and the file writers read its attributes (``IS_FISHEYE``, ``NAMES``, ``RANK``,
...) and never test its name.

>>> get_model("equidistant").IS_FISHEYE, get_model("plumb_bob").NAMES["ros"]
(True, 'plumb_bob')
"""

from __future__ import annotations

from ._double_sphere import DOUBLE_SPHERE
from ._equidistant import EQUIDISTANT
from ._eucm import EUCM
from ._pinhole import PLUMB_BOB, RATIONAL_POLYNOMIAL, THIN_PRISM
from .lens_model import LensModel

__all__ = ["REGISTRY", "MODELS", "get_model", "model_from_file_name"]

REGISTRY: dict[str, LensModel] = {m.NAME: m for m in (
    PLUMB_BOB, RATIONAL_POLYNOMIAL, THIN_PRISM, EQUIDISTANT, DOUBLE_SPHERE, EUCM)}
MODELS = tuple(REGISTRY)


def get_model(name: str) -> LensModel:
    """The model called ``name`` (our name); ValueError naming the known ones otherwise."""
    model = REGISTRY.get(name) if isinstance(name, str) else None
    if model is None:
        raise ValueError(f"unknown lens model {name!r}; expected one of {MODELS}")
    return model


def model_from_file_name(name: str, n_coeffs: int) -> str:
    """Our model name for a file's ``distortion_model`` (ROS, OpenCV, Kalibr names and aliases) with
    ``n_coeffs`` coefficients. Raises ValueError for unknown names and impossible counts."""
    key = str(name).strip().lower()
    n = int(n_coeffs)
    named = REGISTRY.get(key) or next((m for m in REGISTRY.values() if key in m.ALIASES), None)
    found = named.resolve(n) if named is not None else None
    if found is None:
        known = ", ".join(sorted(set(MODELS) | {a for m in REGISTRY.values() for a in m.ALIASES}))
        raise ValueError(f"cannot map distortion_model {name!r} with {n_coeffs} coefficients to a lens model "
                         f"(known: {known})")
    return found
