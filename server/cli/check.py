"""`robocal check`: a quick check of a deployed model over its history, or (--plan N) the poses
every check of the model measures."""

from __future__ import annotations

import argparse

from .common import _whole


def cmd_check(args) -> int:
    if args.plan is not None:
        return _plan(args)
    if args.check is None:
        raise ValueError("check: give the check.csv to judge, or --plan N to plan its poses")
    from robocal.server.checks.check import EXIT_RECALIBRATE, run_check
    from robocal.server.cli.tables import console

    from .. import store
    from ..formats.files import ready_to_write
    from ..formats.model_json import write_json_atomic

    if args.out:
        # before the check is stored: one whose check.json could not be written was appended to
        # the history all the same, and run again, counted twice
        ready_to_write(args.out)
    with store.open_database(args.db) as db:
        res = run_check(args.model, args.check, db)
    if args.out:
        write_json_atomic(args.out, res.to_json())
    if res.warning:
        import sys

        print(f"robocal: warning: {args.check}: {res.warning}", file=sys.stderr)
    console.print(f"{res.verdict} (check {res.history} of this model): {res.reason}")
    return EXIT_RECALIBRATE if res.verdict == "recalibrate" else 0


def _plan(args) -> int:
    """`check --plan N model.json --out check_poses.csv`: the model's check poses."""
    from robocal.server.checks.plan import plan_check, write_plan
    from robocal.server.cli.tables import console

    from ..formats.model_json import read_model

    if args.check is not None:
        raise ValueError(
            f"check --plan: plans the poses of a model; {args.check!r} is not read (drop it)"
        )
    out = args.out or "check_poses.csv"
    plan = plan_check(read_model(args.model), args.plan)
    write_plan(out, plan)
    joints = ", ".join(f"{j}: {v:.1f}" for j, v in plan.joint_zero_mdeg.items())
    left = [f"joint {j}'s zero is a rigid motion" for j in plan.absorbed] + [
        f"joint {j}'s zero moves no pose's SMRs enough to be seen" for j in plan.invisible
    ]
    console.print(
        f"wrote {out}: {len(plan.q)} check poses, {plan.move_s:.1f} s of moves from home; "
        f"one check's standard errors: base or tracker {plan.rigid_mm:.4f} mm, joint zeros "
        f"({joints}) mdeg, scale {plan.scale_ppm:.1f} ppm; D-criterion "
        f"{plan.log_det - plan.log_det_random:+.1f} (log det) over random poses"
        + (f"; {', '.join(left)}" if left else "")
    )
    return 0


def add(sub) -> None:
    """The command's parser, on the command line's subparsers."""
    ck = sub.add_parser(
        "check",
        help="quick check of a deployed model: ok, watch or recalibrate (exit 3), over its "
        "history; --plan N: the poses its checks measure",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="examples:\n"
        "  robocal check model.json check.csv --db history.db --out check.json\n"
        "  robocal check --plan 6 model.json --out check_poses.csv\n"
        "  robocal acquire --check model.json --check-poses check_poses.csv --db history.db",
    )
    ck.add_argument("model", help="model.json (robocal calibrate or diagnose)")
    ck.add_argument(
        "check",
        nargs="?",
        help="check.csv: a meas.csv of the few poses measured every check (not with --plan)",
    )
    ck.add_argument(
        "--db", default="robocal.db", help="database of the checks' history (file or URL)"
    )
    ck.add_argument(
        "--out", help="write check.json here (with --plan: the poses.csv, default check_poses.csv)"
    )
    ck.add_argument(
        "--plan",
        type=_whole(2, 100, "a count of check poses from 2 to 100"),
        metavar="N",
        help="plan the model's N check poses (within the limits, seen by the tracker, a short "
        "path, that show a moved base or tracker, each joint's zero and a scale); the same "
        "model plans the same poses",
    )
    ck.set_defaults(func=cmd_check)
