"""`robocal export`: controller and tool exports of a model."""

from __future__ import annotations

import sys

from .common import _require_deployable


def cmd_export(args) -> None:
    from ..exports import export, format_for

    # plain print: the exports need numpy and the model code only, not rich
    fmt = format_for(args.format, args.out)
    _require_deployable(args)
    for line in export(args.model, fmt, args.out, args.joints, args.targets):
        if line.startswith("warning: "):
            print(f"robocal: {line}", file=sys.stderr)
        else:
            print(line)


def add(sub) -> None:
    """The command's parser, on the command line's subparsers."""
    ex = sub.add_parser(
        "export",
        help="a calibrated model for the controller and other tools: a RAPID module of "
        "joint targets, the parameter table (CSV), a URDF",
    )
    ex.add_argument("model", help="model.json")
    ex.add_argument(
        "--format",
        choices=("rapid", "params", "urdf"),
        help="rapid: MODULE of jointtargets and a PROC moving to them (--joints or --targets); "
        "params: per joint a, alpha, d, theta, beta in the robot's convention, the base and "
        "the SMRs, nominal and calibrated (CSV); urdf: calibrated joint origins, base and SMR "
        "links (default: from the suffix of --out: .mod, .csv, .urdf)",
    )
    joints = ex.add_mutually_exclusive_group()
    joints.add_argument(
        "--joints", help="rapid: joints.csv, the joint commands (robocal compensate)"
    )
    joints.add_argument(
        "--targets", help="rapid: targets.csv, compensated first (as robocal compensate does)"
    )
    ex.add_argument(
        "--out", required=True, help="file to write (the RAPID module's name is its stem)"
    )
    ex.add_argument("--force", action="store_true", help="export a model marked not deployable")
    ex.set_defaults(func=cmd_export)
