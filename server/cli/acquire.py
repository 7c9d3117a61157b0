"""`robocal acquire`: a campaign or a verification run on the cell."""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

from .common import _nonnegative, _nonnegative_int, _positive, _positive_int, _rate, _whole

if TYPE_CHECKING:
    from robocal.server.acquisition.adaptive_plan import AdaptiveSummary
    from robocal.server.acquisition.summary import AcquireSummary

_directions = _whole(1, 6, "a count of directions from 1 to 6")


def _arm(text: str) -> str:
    """An arm's serial number: printable, 1 to 64 characters (the store's rule)."""
    from ..store.checks import arm_name

    try:
        arm = arm_name(text)
    except ValueError as e:
        raise argparse.ArgumentTypeError(str(e)) from None
    assert arm is not None
    return arm


def _verify(args, cell) -> None:
    """`acquire --verify model.json`: the ISO 9283 run before and after compensation."""
    from robocal.server.cli.tables import console, verification_decisions, verification_table
    from robocal.server.verify import run as verification

    opts = verification.VerifyOptions(
        cycles=args.cycles,
        directions=args.directions,
        points_path=args.points,
        side_mm=args.side,
        seed=args.seed,
        name=args.name or "verify",
        effects=tuple(args.effect),
        pause_s=args.pause,
        arm=args.arm,
    )
    with console.status("verifying: nominal joints, then compensated ones..."):
        report = verification.verify(args.db, cell, args.verify, opts)
    out = args.out or "verification.json"
    verification.write(report, out)
    console.print(verification_table(report))
    for line in verification_decisions(report):
        console.print(line, markup=False)
    written = [out]
    if args.certificate:
        from robocal.server.verify.certificate import write_certificate

        write_certificate(report, args.certificate)
        written.append(args.certificate)
    console.print(f"wrote {', '.join(written)}")


def _check(args, cell) -> int:
    """`acquire --check model.json`: the model's check poses measured, judged, stored."""
    from robocal.server.checks.check import EXIT_RECALIBRATE
    from robocal.server.checks.run import CheckRunOptions, acquire_check
    from robocal.server.cli.tables import console

    from ..formats.model_json import write_json_atomic

    if args.check_poses and args.poses is not None:
        raise ValueError("--poses plans that many check poses; --check-poses gives them: not both")
    planned = [o for o, v in (("--name", args.name), ("--order", args.order)) if v]
    if args.choose_from:
        planned.append("--choose-from")
    if planned:
        raise ValueError(
            f"{', '.join(planned)}: a check's poses are planned by `check --plan` (ordered, "
            "chosen) and its campaign named after the model; drop them with --check"
        )
    opts = CheckRunOptions(
        poses_path=args.check_poses,
        poses=args.poses,
        seed=args.seed,
        pause_s=args.pause,
        settle=args.settle,
        beam_break_rate=args.beam_break_rate,
        effects=tuple(args.effect),
        arm=args.arm,
    )
    with _progress(console) as progress:
        run = acquire_check(args.db, cell, args.check, opts, progress=progress, reset=args.reset)
    if run.summary is not None:
        _print_summary(console, run.summary)
    if run.result is None:
        assert run.summary is not None  # a done campaign is always judged
        console.print(
            f"check campaign {run.campaign} {run.summary.state}, not judged; run the same "
            "command again to resume it (with --reset after an e-stop)"
        )
        return 1
    res = run.result
    if run.summary is None:
        console.print(f"check campaign {run.campaign} was measured before: judged now")
    out = args.out or "check.json"
    write_json_atomic(out, res.to_json())
    console.print(f"{res.verdict} (check {res.history} of this model): {res.reason}")
    console.print(f"wrote {out}; the check's history is in {args.db}")
    return EXIT_RECALIBRATE if res.verdict == "recalibrate" else 0


def _progress(console):
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    return Progress(
        TextColumn("{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        console=console,
        transient=True,
    )


def cmd_acquire(args) -> int | None:
    from robocal.server.acquisition.acquire import AcquireOptions, acquire
    from robocal.server.calibration import workflow
    from robocal.server.cli.tables import console

    cell = workflow.load_cell(args.cell)
    if args.cell is not None:  # a robot no controller drives: the cell's file named
        from robocal.server.acquisition.acquire import check_drivable

        try:
            check_drivable(cell)
        except ValueError as e:
            raise workflow.DataError(f"{args.cell}: {e}") from None
    if args.verify and args.check:
        raise ValueError("--verify and --check are two runs: one at a time")
    if args.verify:
        _verify(args, cell)
        return None
    if args.check:
        return _check(args, cell)
    if args.check_poses:
        raise ValueError("--check-poses: the poses of a check, with --check model.json")
    target = args.target_accuracy_mm
    opts = AcquireOptions(
        poses=args.poses if args.poses is not None else (80 if target else 100),
        target_accuracy_mm=target,
        seed=args.seed,
        name=args.name,
        settle=args.settle,
        pause_s=args.pause,
        order=args.order,
        choose_from=args.choose_from,
        beam_break_rate=args.beam_break_rate,
        effects=tuple(args.effect),
        arm=args.arm,
    )
    with _progress(console) as progress:
        summary = acquire(args.db, cell, opts, progress=progress, reset=args.reset)
    _print_summary(console, summary)
    if summary.adaptive:
        _print_adaptive(console, summary.adaptive)
    console.print(
        f"stored in {args.db}; calibrate with: robocal calibrate {args.db} "
        f"--campaign {summary.campaign}"
    )
    return None


def _print_summary(console, summary: AcquireSummary) -> None:
    if summary.resumed_at is not None:
        console.print(
            f"resumed campaign {summary.campaign} ({summary.name}) at pose {summary.resumed_at + 1}"
        )
    locked = summary.locked_without_search_after_10
    console.print(
        f"campaign {summary.campaign} {summary.state}: {summary.measured_poses} poses "
        f"measured now, {summary.readings} readings, {summary.missing} missing, "
        f"{summary.beam_breaks} beam breaks"
        + (
            f"; {'simulated ' if summary.simulated else ''}campaign time "
            f"{summary.campaign_s / 60:.1f} min"
            if summary.campaign_s is not None
            else ""
        )
        + (
            f"; locked without search after pose 10: {100 * locked:.1f}%"
            if locked is not None
            else ""
        )
    )


def _print_adaptive(console, adaptive: AdaptiveSummary) -> None:
    """The adaptive campaign's steps: poses and predicted held-out RMS, and why it stopped."""
    steps = ", ".join(f"{s.poses}: {s.predicted_mm:.4f}" for s in adaptive.steps)
    console.print(f"predicted held-out RMS (mm) by poses: {steps}")
    console.print(f"stopped ({adaptive.stopped}): {adaptive.message}")


def add(sub) -> None:
    """The command's parser, on the command line's subparsers."""
    aq = sub.add_parser(
        "acquire",
        help="run a campaign on the devices (simulated on loopback "
        "sockets by default), storing every reading as it arrives",
    )
    aq.add_argument(
        "--db", default="robocal.db", help="SQLite file (created if absent) or database URL"
    )
    aq.add_argument("--cell", help="cell.json (default: the built-in IRB 2600 cell)")
    aq.add_argument(
        "--poses",
        type=_positive_int,
        help="poses to measure (default 100; with --check: check poses to plan, default 6)",
    )
    aq.add_argument(
        "--seed", type=_nonnegative_int, default=0, help="random seed of the poses (and the cell)"
    )
    aq.add_argument("--name", help="campaign name; an unfinished campaign of that name is resumed")
    aq.add_argument(
        "--arm",
        type=_arm,
        metavar="SERIAL",
        help="the physical arm measured (its serial number, up to 64 printable characters), "
        "stored with the campaign for the fleet view",
    )
    aq.add_argument(
        "--settle",
        choices=("fixed", "adaptive"),
        default="fixed",
        help="fixed pause (the paper's 10 s) or end it once readings agree",
    )
    aq.add_argument(
        "--pause", type=_nonnegative, default=10.0, help="pause at each pose, s (default 10)"
    )
    aq.add_argument("--order", action="store_true", help="order poses to shorten the motion")
    aq.add_argument(
        "--choose-from",
        type=_nonnegative_int,
        default=0,
        metavar="N",
        help="choose the poses out of N candidates by D-optimality",
    )
    aq.add_argument(
        "--target-accuracy-mm",
        type=_positive,
        metavar="T",
        help="an adaptive campaign: a D-optimal seed set, then batches of the poses that most "
        "reduce the predicted held-out error over the working volume, until its predicted "
        "RMS (checked by leave-one-pose-out) reaches T mm, the floor, or --poses (default 80)",
    )
    aq.add_argument(
        "--beam-break-rate",
        type=_rate,
        default=0.0,
        help="simulated cell: fraction of readings lost to a broken beam (0 up to 1)",
    )
    aq.add_argument(
        "--effect",
        action="append",
        default=[],
        metavar="SPEC",
        help="hidden effects of the simulated arm; see `simulate --help`",
    )
    aq.add_argument(
        "--verify",
        metavar="MODEL",
        help="an ISO 9283 verification run of model.json: each test point visited from several "
        "directions and cycles, with the nominal joints and the compensated ones",
    )
    aq.add_argument("--points", help="verify at these points (points.csv), not the ISO cube")
    aq.add_argument("--cycles", type=_positive_int, default=3, help="verification cycles")
    aq.add_argument("--directions", type=_directions, default=3, help="approach directions (1-6)")
    aq.add_argument("--side", type=_positive, default=400.0, help="the ISO cube's side, mm")
    aq.add_argument(
        "--check",
        metavar="MODEL",
        help="a quick check of model.json: its check poses (--check-poses; else those of its "
        "first check in --db; else planned as `check --plan` does, --poses of them, default 6) "
        "measured, judged and appended to the model's history in --db",
    )
    aq.add_argument(
        "--check-poses",
        metavar="FILE",
        help="with --check: the poses to measure, a poses.csv (`robocal check --plan`)",
    )
    aq.add_argument(
        "--out",
        help="the verification's figures (default verification.json); with --check: check.json",
    )
    aq.add_argument("--certificate", help="also write the accuracy certificate (HTML) here")
    aq.add_argument(
        "--reset",
        action="store_true",
        help="resume an e-stopped campaign (after the cell was checked)",
    )
    aq.set_defaults(func=cmd_acquire)
