"""Calibrate a camera from a web page: the feed, the detected corners, where to hold the board next.

    python -m aicalib_tf.live --pattern 9x6 --square 25mm [--out calib/] [--port 8765]
        (or --board charuco:11x8,square=30mm,marker=22mm,dict=DICT_5X5_100 for a ChArUco board)
        [--source video.mp4 | --camera 0 | --source rtsp://...] [--target 0.1px] [--max-views 40]

Open the printed address in a browser: it holds a random token made for this run (as Jupyter's
does), without which the page's data and its Save are refused; requests that do not name this
server's address, or come from another web site, are refused too. Without ``--source``/``--camera`` the page asks for the
browser's own camera (a laptop's or a phone's; browsers allow cameras on ``localhost`` or over
https), and sends its frames to this server; with one, the server reads the source and the page
shows it. Each frame goes through the guided loop of ``python -m aicalib_tf.calibrate video.mp4``:
the page draws the detected corners (green: the view was kept), the coverage of the image, the
next view to show ("a board in the top-left, turned left about its vertical axis"), what is still
missing, and the verdict (the predicted projection uncertainty against ``--target``). "Save
calibration" writes the files of the photo path into ``--out`` (camera.yaml, camera.json,
camera_info.yaml, report.png, report.txt). ``--host 0.0.0.0`` serves other machines too.
A ChArUco board (``--board``) names each corner by the markers beside it: a board cut by the
frame is a view, and the page writes each corner's id beside it. A Kalibr AprilGrid (``--board
aprilgrid:6x6,tag=88mm,spacing=0.3`` or a Kalibr target YAML) names the corners by their tags
likewise: the page writes each tag's id at its centre.

Exit codes: 0 after Ctrl-C; 2 bad input (a bad pattern, square or board, a port in use, a source that
cannot be opened).
"""

from __future__ import annotations

import sys

DEFAULT_PORT = 8765


def build_parser():
    """The command line's parser (docs/cli.md is generated from it)."""
    from aicalib_tf.calib.workflow import DETECTORS
    from aicalib_tf.cli import parser
    from aicalib_tf.cnn.spec import DETECTOR_NETWORK, NETWORK_HELP

    ap = parser("python -m aicalib_tf.live", __doc__)
    ap.add_argument("--pattern", help="inner corners, COLSxROWS, e.g. 9x6 (or --board)")
    ap.add_argument("--board", help="a ChArUco board instead of --pattern and --square: "
                                    "charuco:11x8,square=30mm,marker=22mm,dict=DICT_5X5_100[,legacy][,first=0]; "
                                    "an AprilGrid: aprilgrid:6x6,tag=88mm,spacing=0.3; or a Kalibr target.yaml")
    ap.add_argument("--square", default="1", help="square size with unit, e.g. 25mm (default: 1, unitless)")
    ap.add_argument("--out", default="calib", help="where Save writes the calibration (default: %(default)s)")
    ap.add_argument("--source", default=None, help="a video file, image glob or stream URL read by the server")
    ap.add_argument("--camera", default=None, help="a camera index read by the server, e.g. 0")
    ap.add_argument("--host", default="127.0.0.1", help="address to serve on (default: %(default)s)")
    ap.add_argument("--port", type=int, default=DEFAULT_PORT, help="port (default: %(default)s; 0 picks a free one)")
    ap.add_argument("--model", default="auto", help="lens model: auto or a forced one (default: %(default)s)")
    ap.add_argument("--detector", default="cnn", choices=DETECTORS, help="corner detector (default: %(default)s)")
    ap.add_argument("--network", default=DETECTOR_NETWORK, help=NETWORK_HELP)
    ap.add_argument("--target", default="0.1px", help="stop when the predicted uncertainty reaches this (default: %(default)s)")
    ap.add_argument("--max-views", type=int, default=40, help="stop after this many kept views (default: %(default)s)")
    return ap


def _parse_args(argv):
    return build_parser().parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    """Serve the page until Ctrl-C; 2 with one error line for bad input."""
    from aicalib_tf.cli import run_main

    args = _parse_args(argv)
    return run_main(lambda: _main(args), debug=args.debug)


def _config(args):
    from aicalib_tf.calib.workflow import parse_square
    from aicalib_tf.geometry.lens import MODELS
    from aicalib_tf.geometry.pattern import check_pattern, parse_pattern
    from aicalib_tf.guided.session import check_max_views
    from aicalib_tf.guided.workflow import parse_target
    from aicalib_tf.live.server import LiveConfig
    from aicalib_tf.outfolder import check_out_path

    if args.source is not None and args.camera is not None:
        raise ValueError("give --source or --camera, not both")
    if args.model != "auto" and args.model not in MODELS:
        raise ValueError(f"unknown --model {args.model!r}; choose auto or one of {', '.join(MODELS)}")
    if not 0 <= args.port <= 65535:
        raise ValueError(f"--port must be in 0..65535, got {args.port}")
    check_max_views(args.max_views)
    check_out_path(args.out)
    if args.board:
        if args.pattern:
            raise ValueError("give --pattern (a chessboard) or --board (a marker board), not both")
        from aicalib_tf.geometry.aprilgrid import AprilGrid, Checkerboard
        from aicalib_tf.geometry.boards import read_board

        b = read_board(args.board, circles_refused="the live page")
        pattern, square, unit = b.pattern_size, float(b.square_size if isinstance(b, AprilGrid) else b.square), b.unit
        board = None if isinstance(b, Checkerboard) else args.board  # a Kalibr checkerboard: a chessboard
    elif not args.pattern:
        raise ValueError("give --pattern COLSxROWS (a chessboard) or --board charuco:... or aprilgrid:... (a marker board)")
    else:
        pattern, board = check_pattern(parse_pattern(args.pattern)), None
        square, unit = parse_square(args.square)
    return LiveConfig(pattern=pattern, square=square, square_unit=unit, board=board, out=args.out,
                      source=args.source if args.source is not None else args.camera,
                      detector=args.detector, network=args.network, model=args.model,
                      target_px=parse_target(args.target), max_views=args.max_views)


def _main(args) -> int:
    import asyncio

    from aicalib_tf.calib.workflow import make_detector
    from aicalib_tf.guided.workflow import board_target
    from aicalib_tf.live.server import LiveState, make_app

    cfg = _config(args)
    if cfg.source is not None:
        from aicalib_tf.sources import open_source

        open_source(cfg.source).close()  # a source that cannot be opened fails here, with its name
    from aicalib_tf.live.server import tracking_detector

    detector = make_detector(cfg.detector, board_target(cfg), cfg.network)
    if cfg.detector == "cnn" and not cfg.board:  # a chessboard stream: follow the board from frame to frame
        detector = tracking_detector(cfg.pattern, cfg.network, detector)
    state = LiveState(cfg, detector)
    try:
        asyncio.run(_serve(make_app(state, host=args.host), args.host, args.port))
    except KeyboardInterrupt:
        print("stopped", file=sys.stderr)
    return 0


def page_url(host: str, port: int, token: str) -> str:
    """The address to open: ``http://localhost:PORT/?token=...`` (the bound host when it is not this machine's any/loopback)."""
    shown = "localhost" if host in ("127.0.0.1", "0.0.0.0", "::", "") else (f"[{host}]" if ":" in host else host)
    return f"http://{shown}:{port}/?token={token}"


async def _serve(app, host: str, port: int) -> None:
    import asyncio

    from aiohttp import web

    from aicalib_tf.live.server import token_of

    runner = web.AppRunner(app, access_log=None)
    await runner.setup()
    site = web.TCPSite(runner, host, port)
    try:
        await site.start()
    except OSError as exc:
        await runner.cleanup()
        raise OSError(exc.errno, f"cannot serve on {host}:{port}: {exc.strerror}") from None
    bound = runner.addresses[0][1] if runner.addresses else port
    print(f"live calibration page: {page_url(host, bound, token_of(app))}", flush=True)
    try:
        await asyncio.Event().wait()
    finally:
        await runner.cleanup()


if __name__ == "__main__":
    sys.exit(main())
