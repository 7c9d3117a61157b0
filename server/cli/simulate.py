"""`robocal simulate`: a campaign from the virtual cell."""

from __future__ import annotations

import argparse
import sys

import numpy as np

from .common import _nonnegative, _nonnegative_int, _positive_int, _rate


def _fraction(text: str) -> float:
    v = _nonnegative(text)
    if v > 1:
        raise argparse.ArgumentTypeError(f"{text!r} is not a fraction between 0 and 1")
    return v


def cmd_simulate(args) -> None:
    from robocal.drivers.cell import TrackerSpec, VirtualCell
    from robocal.drivers.effects import make_effects
    from robocal.server.calibration import workflow
    from robocal.server.cli.tables import console

    from ..formats.campaign_csv import write_campaign
    from ..formats.model_json import write_json_atomic

    cell = workflow.load_cell(args.cell)
    vc = VirtualCell.random(
        cell.robot,
        cell.targets,
        seed=args.seed,
        tracker=TrackerSpec.of(cell.tracker),
        base=cell.base,  # a wall or ceiling mount: the arm where the cell says, gravity with it
    )
    vc.effects.extend(make_effects(args.effect, vc, args.seed))  # bad specs fail before any output
    meas = vc.campaign(
        args.poses,
        seed=args.seed,
        beam_break_rate=args.beam_break_rate,
        arm_scatter_deg=args.arm_scatter_deg,
        targets_per_pose=args.targets_per_pose,
        outlier_rate=args.outlier_rate,
        noise_scale=args.noise_scale,
    )
    write_campaign(args.out, meas)
    for why in _unseen(vc, meas):
        print(f"robocal: warning: {args.out}: {why}", file=sys.stderr)
    truth = vc.truth()
    truth["noise_floor_mm"] = vc.noise_floor_mm(meas.q, args.noise_scale)
    if args.truth_out:
        write_json_atomic(args.truth_out, truth)
    console.print(
        f"wrote {meas.n_poses} poses x {len(meas.target_names)} targets "
        f"({meas.n_readings} readings) to {args.out}; "
        f"tracker noise floor {truth['noise_floor_mm']:.4f} mm RMS; effects: "
        + (", ".join(e.label() for e in vc.effects) or "none")
    )


# a compliance turning its joint less than this over the campaign moves an SMR a metre away 1 um,
# a tenth of a tracker's noise (a SCARA's joint 2, its axis tilted by its geometric errors: 2.6e-7)
UNSEEN_RAD = 1e-6


def _unseen(vc, meas) -> list[str]:
    """A sentence per compliance that does not show in the campaign: the gravity torque about
    its joint does not change over the poses (a SCARA's vertical axes), nothing to find."""
    out = []
    for e in vc.effects:
        if e.name != "joint_compliance":
            continue
        dq = e.joint_offsets(vc, meas.q, None, None)[:, e.joint]
        if np.ptp(dq) < UNSEEN_RAD:
            out.append(
                f"{e.label()} turns joint {e.joint + 1} by {np.degrees(np.ptp(dq)):.1g} deg over "
                f"the campaign: the gravity torque about its axis does not change on this arm (an "
                "axis along gravity), so the data holds nothing of it"
            )
    return out


def add(sub) -> None:
    """The command's parser, on the command line's subparsers."""
    s = sub.add_parser("simulate", help="a campaign from the virtual cell")
    s.add_argument("--cell", help="cell.json (default: the built-in IRB 2600 cell)")
    s.add_argument(
        "--poses", type=_positive_int, default=100, help="poses to measure (default 100)"
    )
    s.add_argument(
        "--seed", type=_nonnegative_int, default=0, help="random seed of the cell and the poses"
    )
    s.add_argument(
        "--beam-break-rate",
        type=_rate,
        default=0.0,
        help="fraction of readings lost to a broken beam (0 up to 1, default 0)",
    )
    s.add_argument(
        "--arm-scatter-deg",
        type=_nonnegative,
        default=0.0,
        help="the arm's repeatability: a joint error drawn afresh per pose (std, deg "
        "per joint), shared by every SMR of the pose",
    )
    s.add_argument(
        "--targets-per-pose",
        type=_positive_int,
        default=None,
        help="measure only this many random SMRs per pose (the others absent)",
    )
    s.add_argument(
        "--outlier-rate",
        type=_fraction,
        default=0.0,
        help="fraction of readings displaced 0.3-2 mm in a random direction (a "
        "mis-lock or a bumped SMR), listed in the truth file",
    )
    s.add_argument(
        "--noise-scale",
        type=_nonnegative,
        default=1.0,
        help="tracker noise as a multiple of its spec (default 1)",
    )
    s.add_argument("--out", required=True, help="meas.csv to write")
    s.add_argument("--truth-out", help="also write the simulated truth as JSON")
    from robocal.drivers.effects import spec_help
    from robocal.solver.vocabulary import KINDS

    s.add_argument(
        "--effect",
        action="append",
        default=[],
        metavar="SPEC",
        help=(
            "add a physical effect, NAME[:JOINT[:HARMONIC]][=MAGNITUDE], joints from 1; repeatable. "
            + spec_help(KINDS)
        ),
    )
    s.set_defaults(func=cmd_simulate)
