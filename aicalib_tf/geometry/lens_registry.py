"""The lens-model registry: every model's name to its implementation (:class:`~aicalib_tf.geometry.lens_model.LensModel`).

A new model is one module beside the others and one entry in :data:`REGISTRY`; the renderer, the
fit, the model choice and the file writers read its attributes (``IS_FISHEYE``, ``NAMES``, ``RANK``,
...) and never test its name.

A family whose layout is part of the model's name (the spline's knot grid) is listed once, by its
bare name; :data:`REGISTRY` resolves its other names through :meth:`~aicalib_tf.geometry.lens_model.LensModel.variant`
(``name in REGISTRY``, ``REGISTRY[name]``, ``name in MODELS`` hold for them), without listing them.

>>> get_model("equidistant").IS_FISHEYE, get_model("plumb_bob").NAMES["ros"]
(True, 'plumb_bob')
>>> get_model("splined_equidistant_nx=8_ny=6_fov=120_smooth=1").n_coeffs
100
"""

from __future__ import annotations

from ._double_sphere import DOUBLE_SPHERE
from ._equidistant import EQUIDISTANT
from ._eucm import EUCM
from ._pinhole import PLUMB_BOB, RATIONAL_POLYNOMIAL, THIN_PRISM
from ._splined import SPLINED
from .lens_model import LensModel

__all__ = ["REGISTRY", "MODELS", "get_model", "model_from_file_name", "per_model"]


class _Registry(dict):
    """{name: model} of the listed models; a family's configured names resolve on lookup (module docstring)."""

    def __missing__(self, key):
        found = next((v for v in (m.variant(key) for m in list(self.values())) if v is not None), None)
        if found is None:
            raise KeyError(key)
        return found

    def __contains__(self, key):
        return self.get(key) is not None

    def get(self, key, default=None):
        try:
            return self[key] if isinstance(key, str) else default
        except KeyError:
            return default


class _Names(tuple):
    """The listed model names; ``in`` also holds for a family's configured names."""

    def __contains__(self, key):
        return key in REGISTRY


def per_model(fn) -> dict:
    """{name: fn(model)} over the listed models, computed on lookup for a family's configured names."""

    class _PerModel(dict):
        def __missing__(self, key):
            return fn(REGISTRY[key])

        def __contains__(self, key):
            return key in REGISTRY

    return _PerModel({name: fn(m) for name, m in REGISTRY.items()})


REGISTRY: dict[str, LensModel] = _Registry({m.NAME: m for m in (
    PLUMB_BOB, RATIONAL_POLYNOMIAL, THIN_PRISM, EQUIDISTANT, DOUBLE_SPHERE, EUCM, SPLINED)})
MODELS = _Names(REGISTRY)


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
