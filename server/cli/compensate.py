"""`robocal compensate`: joint commands that put the SMRs where wanted."""

from __future__ import annotations

import argparse
import sys

from .common import _nonnegative, _require_deployable


def _tcp(text: str) -> list[float]:
    from robocal.server.compensate.compensation import parse_tcp

    try:
        return parse_tcp(text)
    except ValueError as e:
        raise argparse.ArgumentTypeError(str(e)) from None


def cmd_compensate(args) -> None:
    from robocal.server.compensate.compensation import Limits, run

    _require_deployable(args)
    limits = Limits(args.max_error_mm, args.max_move_deg, args.max_jump_deg)
    s = run(args.model, args.targets, args.out, args.tcp, limits)
    for w in s["warnings"]:
        print(f"robocal: warning: {args.targets}: {w}", file=sys.stderr)
    # plain print, as predict: the command starts with numpy alone
    print(
        f"compensated {s['poses']} poses to {args.out}: predicted error RMS {s['rms_mm']:.4f} mm, "
        f"worst {s['worst_mm']:.4f} mm, in {s['seconds']:.2f} s"
    )
    if s["jumps"]:
        print(s["jumps"])


def add(sub) -> None:
    """The command's parser, on the command line's subparsers."""
    cp = sub.add_parser(
        "compensate", help="joint commands that put the SMRs (or a tool point) where wanted"
    )
    cp.add_argument("model", help="model.json (robocal calibrate)")
    cp.add_argument(
        "targets",
        help="targets.csv: pose, target, x, y, z and q1..qN or cf1, cf4, cf6, cfx "
        "[, time_s, temp_c, prev_q1..prev_qN]",
    )
    cp.add_argument(
        "--out", default="joints.csv", help="joint commands to write (default joints.csv)"
    )
    cp.add_argument(
        "--tcp",
        type=_tcp,
        metavar="X,Y,Z[,RX,RY,RZ]",
        help="a tool in the flange frame (mm; orientation Rz Ry Rx in degrees): targets.csv "
        "then gives target TCP, and optionally rx, ry, rz for the tool's orientation "
        "(--tcp=-10,... when it starts with a minus)",
    )
    cp.add_argument(
        "--max-error-mm",
        type=_nonnegative,
        default=0.1,
        help="refuse a pose the model cannot bring closer than this (default 0.1 mm RMS)",
    )
    cp.add_argument(
        "--max-move-deg",
        type=_nonnegative,
        default=10.0,
        help="refuse a pose whose joints move further than this from its starting joints: "
        "another configuration (default 10 deg)",
    )
    cp.add_argument(
        "--max-jump-deg",
        type=_nonnegative,
        default=90.0,
        help="report consecutive poses whose joints turn more than this (default 90 deg)",
    )
    cp.add_argument("--force", action="store_true", help="use a model marked not deployable")
    cp.set_defaults(func=cmd_compensate)
