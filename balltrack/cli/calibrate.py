"""``balltrack calibrate IMAGES... --board 9x6 --square 0.025 -o camera.yaml``: a camera's
intrinsics and lens distortion from photos of a printed chessboard (OpenCV's calibration),
written as a ROS camera_info YAML file for the camera service's ``calibration`` setting.

``--board`` counts the inner corners (where four squares meet) along a row and a column: a
board of 10 x 7 squares has 9x6. Take 10-20 photos of it at different angles and distances,
reaching the corners of the frame, all at the size the camera will run at.
"""

import argparse
import glob
import os
import sys

from balltrack.common.arguments import number, unwritable_reason


def command_calibrate(args) -> int:
    from balltrack.common.images import UnreadableImage, read_image

    from balltrack.services.camera.calibration import calibrate, parse_board, write_calibration

    def fail(message: str) -> int:
        print(f"balltrack calibrate: {message}", file=sys.stderr)
        return 2

    try:
        board = parse_board(args.board)
    except ValueError as error:
        return fail(str(error))
    unwritable = unwritable_reason(args.output)
    if unwritable:  # (before the images are read and the board searched for in each)
        return fail(f"{args.output}: cannot write ({unwritable})")
    paths = []
    for pattern in args.images:  # patterns too, for shells that do not expand them
        matches = sorted(glob.glob(pattern)) if any(character in pattern for character in "*?[") else [pattern]
        paths += [path for path in matches if os.path.isfile(path)] or [pattern]
    images = []
    for path in paths:
        try:
            image = read_image(path)
        except UnreadableImage as error:
            image = None
            print(f"{path}: cannot read image ({error})", file=sys.stderr)
        images.append((path, image))
    try:
        result = calibrate(images, board, args.square, args.name)
    except ValueError as error:
        return fail(str(error))
    for path in result.skipped:
        print(f"{path}: no whole {board[0]}x{board[1]} board found, skipped", file=sys.stderr)
    try:
        write_calibration(args.output, result.model)
    except OSError as error:
        return fail(f"{args.output}: cannot write ({error.strerror or error})")
    model = result.model
    print(f"{len(result.used)} of {len(images)} images used; {model.width}x{model.height}, "
          f"fx {model.fx:.2f} fy {model.fy:.2f} cx {model.cx:.2f} cy {model.cy:.2f} px, "
          f"distortion {', '.join(f'{value:.4f}' for value in model.distortion)}")
    print(f"reprojection error {result.rms_px:.3f} px (RMS); written to {args.output}")
    return 0


def register(commands) -> None:
    parser = commands.add_parser("calibrate", help="camera calibration from chessboard photos",
                                 description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("images", nargs="+", metavar="IMAGE", help="photos of the board (or glob patterns)")
    parser.add_argument("--board", default="9x6", help="inner corners per row x per column (default 9x6)")
    # (a square of 1e308 m made OpenCV's calibration fail an assertion: a traceback)
    parser.add_argument("--square", type=number(above=0, maximum=10), required=True,
                        help="side of one square (metres, at most 10)")
    parser.add_argument("-o", "--output", default="camera.yaml", help="the YAML file to write (default camera.yaml)")
    parser.add_argument("--name", default="camera", help="camera_name written in the file")
    parser.set_defaults(handler=command_calibrate)
