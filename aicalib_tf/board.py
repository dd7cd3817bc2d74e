"""Write a printable ChArUco board or Kalibr AprilGrid, its description printed beneath it.

    python -m aicalib_tf.board "charuco:11x8,square=30mm,marker=22mm,dict=DICT_5X5_100" --out board.pdf
        [--paper A4|A3|A2|letter] [--dpi 300]
    python -m aicalib_tf.board "aprilgrid:6x6,tag=20mm,spacing=0.3" --out grid.pdf

An AprilGrid (or a Kalibr ``target_type: aprilgrid`` YAML) is drawn from its layout
(:mod:`aicalib_tf.geometry.aprilgrid`): tags with a two-bit black border and a black square of the
gap's side at every tag corner, as Kalibr prints it.

The board is drawn by OpenCV (``cv2.aruco.CharucoBoard.generateImage``) at its true size on the
paper (the longer side of the board along the longer side of the paper), centred, with the
description in small type below it: the same text ``--board`` takes in ``calibrate`` and
``detect``. ``--out`` ending in .pdf writes a vector page with the board as an exact bitmap (print
at 100 %, no "fit to page"); .png writes a bitmap of the page at ``--dpi``. The lengths need a
unit (mm, cm, m, in). Exit codes: 0 written; 2 bad input (a bad board, a board larger than the
paper, an unknown paper or file type).
"""

from __future__ import annotations

import io
import sys

import cv2
import numpy as np

from aicalib_tf.geometry.charuco import UNIT_MM

__all__ = ["main", "PAPERS", "page_image", "page_pdf"]

PAPERS = {"a4": (210.0, 297.0), "a3": (297.0, 420.0), "a2": (420.0, 594.0), "letter": (215.9, 279.4)}
MARGIN_MM = 10.0


def _layout(board, paper: str) -> tuple[tuple[float, float], tuple[float, float], float]:
    """((paper w, h) mm, (board x0, y0) mm on the page, square mm): landscape when the board is wider."""
    if not UNIT_MM.get(board.unit):  # unitless: no size on paper
        what = "tag=" if hasattr(board, "tag_ids") else "square= and marker="
        raise ValueError(f"board {board.describe()}: give {what} a unit (mm, cm, m, in) to print it")
    try:
        pw, ph = PAPERS[paper.lower()]
    except KeyError:
        raise ValueError(f"--paper must be one of {', '.join(PAPERS)}, got {paper!r}") from None
    cells, sq = _cells(board)
    bw, bh = cells[0] * sq, cells[1] * sq
    if bw > bh:
        pw, ph = ph, pw
    if bw > pw - 2 * MARGIN_MM or bh > ph - 2 * MARGIN_MM - 8.0:
        raise ValueError(f"the board is {bw:g} x {bh:g} mm; it does not fit on {paper} paper "
                         f"({pw:g} x {ph:g} mm with {MARGIN_MM:g} mm margins): choose a larger --paper or smaller squares")
    return (pw, ph), ((pw - bw) / 2.0, (ph - bh) / 2.0 - 4.0), sq


def _cells(board) -> tuple[tuple[int, int], float]:
    """((across, down), mm): the board's printed extent in cells of that side, a ChArUco board's
    squares or an AprilGrid's lattice units (its corner squares beyond the outer tags included)."""
    if hasattr(board, "tag_ids"):  # an AprilGrid (aicalib_tf.geometry.aprilgrid)
        a = board.fraction[0]
        return (board.pattern_size[0] - 1 + 2 * a, board.pattern_size[1] - 1 + 2 * a), board.square_size * UNIT_MM[board.unit]
    return tuple(board.squares), board.square * UNIT_MM[board.unit]


def _board_pixels(board, square_px: int) -> np.ndarray:
    """(Y·p, X·p) uint8 board drawn by OpenCV, p = ``square_px`` or the nearest size OpenCV draws
    (``generateImage`` refuses a few sizes; a PDF places the bitmap at the exact size anyway)."""
    if hasattr(board, "tag_ids"):  # an AprilGrid, drawn from its layout: p px per lattice unit
        from aicalib_tf.geometry.aprilgrid import layout_image

        return layout_image(board, square_px, board.fraction[0] * square_px)
    X, Y = board.squares
    cv = board.to_opencv()
    for p in sorted(range(max(square_px - 3, 1), square_px + 4), key=lambda q: abs(q - square_px)):
        try:
            return cv.generateImage((X * p, Y * p), marginSize=0, borderBits=1)
        except cv2.error:
            continue
    raise ValueError(f"OpenCV cannot draw this board at {square_px} px per square; try another --dpi")


def page_image(board, paper: str = "A4", dpi: int = 300) -> np.ndarray:
    """(H, W) uint8 page at ``dpi``: white paper, the board at its size, the description below."""
    (pw, ph), (x0, y0), sq = _layout(board, paper)
    mm = dpi / 25.4
    page = np.full((int(round(ph * mm)), int(round(pw * mm))), 255, np.uint8)
    img = _board_pixels(board, max(int(round(sq * mm)), 1))
    r0, c0 = int(round(y0 * mm)), int(round(x0 * mm))
    page[r0: r0 + img.shape[0], c0: c0 + img.shape[1]] = img
    scale = max(dpi / 300.0, 0.3)
    cv2.putText(page, board.describe(), (c0, r0 + img.shape[0] + int(round(5 * mm))), cv2.FONT_HERSHEY_SIMPLEX,
                scale, 0, max(1, int(round(2 * scale))), cv2.LINE_AA)
    return page


def page_pdf(board, paper: str = "A4", dpi: int = 300) -> bytes:
    """One PDF page: the board (bitmap at ``dpi``, placed at its exact size) and its description."""
    from aicalib_tf.plotting import new_figure

    (pw, ph), (x0, y0), sq = _layout(board, paper)
    img = _board_pixels(board, max(int(round(sq * dpi / 25.4)), 1))
    fig = new_figure((pw / 25.4, ph / 25.4))
    cells, _ = _cells(board)
    bw, bh = cells[0] * sq, cells[1] * sq
    ax = fig.add_axes((x0 / pw, 1.0 - (y0 + bh) / ph, bw / pw, bh / ph))
    ax.imshow(img, cmap="gray", vmin=0, vmax=255, interpolation="nearest", aspect="auto")
    ax.set_axis_off()
    fig.text(x0 / pw, 1.0 - (y0 + bh + 6.0) / ph, board.describe(), fontsize=8, family="monospace")
    buf = io.BytesIO()
    fig.savefig(buf, format="pdf", dpi=dpi)
    return buf.getvalue()


def build_parser():
    """The command line's parser (also read by :mod:`aicalib_tf.docs`)."""
    from aicalib_tf.cli import parser

    ap = parser("python -m aicalib_tf.board", __doc__)
    ap.add_argument("board", help="charuco:XxY,square=30mm,marker=22mm,dict=DICT_5X5_100[,legacy][,first=0], "
                                  "aprilgrid:6x6,tag=88mm,spacing=0.3[,family=tag36h11][,first=0] or a Kalibr aprilgrid target.yaml")
    ap.add_argument("--out", required=True, help="board.pdf or board.png")
    ap.add_argument("--paper", default="A4", help=f"one of {', '.join(PAPERS)} (default: %(default)s)")
    ap.add_argument("--dpi", type=int, default=300, help="pixels per inch of the board bitmap (default: %(default)s)")
    return ap


def _parse_args(argv):
    return build_parser().parse_args(argv)


def _main(args) -> int:
    from aicalib_tf.geometry.aprilgrid import AprilGrid
    from aicalib_tf.geometry.boards import read_board
    from aicalib_tf.io import atomic_write_bytes

    board = read_board(args.board, circles_refused="the board printer (it prints ChArUco boards and AprilGrids)")
    if not isinstance(board, AprilGrid) and not hasattr(board, "squares"):
        raise ValueError(f"{args.board}: a Kalibr checkerboard is a chessboard; this prints ChArUco boards and AprilGrids")
    if not 50 <= args.dpi <= 1200:
        raise ValueError(f"--dpi must be between 50 and 1200, got {args.dpi}")
    out = str(args.out)
    if out.lower().endswith(".pdf"):
        data = page_pdf(board, args.paper, args.dpi)
    elif out.lower().endswith(".png"):
        ok, png = cv2.imencode(".png", page_image(board, args.paper, args.dpi))
        data = png.tobytes()
    else:
        raise ValueError(f"--out {out}: must end in .pdf or .png")
    atomic_write_bytes(out, data)
    print(f"wrote {out}: {board.describe()} on {args.paper} paper; print at 100 % scale")
    return 0


def main(argv: list[str] | None = None) -> int:
    """Write the board (see the module docstring); exit 2 on bad input."""
    from aicalib_tf.cli import run_main

    args = _parse_args(argv)
    return run_main(lambda: _main(args), debug=args.debug)


if __name__ == "__main__":
    sys.exit(main())
