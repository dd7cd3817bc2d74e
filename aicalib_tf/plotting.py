"""Matplotlib figures for files, without pyplot's global state.

The library draws its figures (benchmark plots, ``report.png``) on ``matplotlib.figure.Figure``
objects that are not registered with pyplot. So it never switches the user's backend (a notebook
keeps ``%matplotlib inline``), never leaves figures open, and works headless.
"""

from __future__ import annotations

import io

__all__ = ["new_figure", "png_bytes"]


def new_figure(figsize: tuple[float, float]):
    """A fresh ``matplotlib.figure.Figure`` of ``figsize`` inches, outside pyplot."""
    from matplotlib.figure import Figure

    return Figure(figsize=figsize)


def png_bytes(fig, *, dpi: int = 90, tight: bool = True) -> bytes:
    """Render ``fig`` to PNG bytes (``bbox_inches="tight"`` when ``tight``)."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi, **({"bbox_inches": "tight"} if tight else {}))
    return buf.getvalue()
