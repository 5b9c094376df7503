"""``conveyor-twin animate RUN.mcap -o run.gif|run.mp4``: render a recording as an animation.

Shows the parts at their poses and sizes on the cell drawn to scale (from the recording's
``cell.yaml``), the macro density as a heat map, light barriers red while blocked, actuators
at their position, and under it the light-barrier states and belt speeds against time. The
speed-up sets how many simulated seconds pass per second of animation, exactly: a GIF's frame
delays (whole 10 ms) alternate so that they add up to the simulated time / speed-up (70, 60,
70 ms at 15 frames/s); a GIF plays at most 50 frames/s. GIF is written with Pillow; MP4 needs
ffmpeg. The density has the colour map and scale of ``plot``'s density figure (0 to the
cell's ρ_max); zero density is left transparent. Exit codes: 0 written, 1 the recording
cannot be animated (nothing written), 2 bad options.
"""

import argparse
import sys
from typing import List, Optional

from conveyor_twin.record.errors import RecordingError
from conveyor_twin.wire.cdr import CdrError

DEFAULT_FPS = 15.0
DEFAULT_SPEED = 1.0


def _view(text: str) -> List[float]:
    values = [float(v) for v in text.split(',') if v.strip()]
    if len(values) not in (2, 4):
        raise argparse.ArgumentTypeError(f'{text!r}: expected X0,X1 or X0,X1,Y0,Y1 [m]')
    if values[1] <= values[0] or (len(values) == 4 and values[3] <= values[2]):
        raise argparse.ArgumentTypeError(f'{text!r}: each range must be increasing')
    return values


def _positive(text: str) -> float:
    value = float(text)
    if not value > 0.0:
        raise argparse.ArgumentTypeError(f'{text!r}: expected a positive number')
    return value


def build_parser() -> argparse.ArgumentParser:
    """Return the argument parser of ``animate``."""
    p = argparse.ArgumentParser(prog='conveyor-twin animate', description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument('file', help='MCAP recording of the twin (needs its parts stream)')
    p.add_argument('-o', '--output', required=True, help='animation file: .gif or .mp4')
    p.add_argument('--speed', type=_positive, default=DEFAULT_SPEED,
                   help='speed-up: simulated seconds per second of animation (default 1)')
    p.add_argument('--fps', type=_positive, default=DEFAULT_FPS,
                   help='frames per second of the animation (default 15)')
    p.add_argument('--start', type=float, default=None, help='first simulation time [s]')
    p.add_argument('--end', type=float, default=None, help='last simulation time [s]')
    p.add_argument('--view', type=_view, default=None,
                   help='region to show, X0,X1 or X0,X1,Y0,Y1 [m] (default: the whole cell)')
    p.add_argument('--width', type=_positive, default=None,
                   help='figure width [in] (default: from the shape of the view, 8 to 13)')
    p.add_argument('--dpi', type=int, default=90, help='resolution [dots per inch]')
    p.add_argument('--quiet', action='store_true', help='no progress bar')
    return p


def main(argv: Optional[List[str]] = None) -> int:
    """Entry point of ``conveyor-twin animate``."""
    args = build_parser().parse_args(argv)
    from conveyor_twin.viz.animation import (AnimationError, check_fps, check_output, render,
                                             stderr_progress)
    from conveyor_twin.viz.frames import load_frames
    try:
        check_fps(check_output(args.output), args.fps)
    except AnimationError as exc:
        print(f'conveyor-twin animate: {exc}', file=sys.stderr)
        return 2
    try:
        data = load_frames(args.file, fps=args.fps, speed=args.speed, start_s=args.start,
                           end_s=args.end)
    except (RecordingError, CdrError) as exc:
        print(f'conveyor-twin animate: {exc}', file=sys.stderr)
        return 1
    try:
        count = render(data, args.output, fps=args.fps, dpi=args.dpi, width=args.width,
                       view=args.view, progress=None if args.quiet else stderr_progress)
    except AnimationError as exc:
        print(f'conveyor-twin animate: {exc}', file=sys.stderr)
        return 1
    print(f'{args.output}: {count} frames, {data.start_s:.3f}..{data.end_s:.3f} s simulated '
          f'at {args.speed:g}x, {args.fps:g} frames/s')
    return 0


if __name__ == '__main__':
    sys.exit(main(sys.argv[1:]))
