"""What the commands share: argument types and groups, data loading, printing."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from collections.abc import Sequence

    from robocal.server.formats.blocks import Unexplained
    from robocal.server.formats.report_doc import Extrapolation, ReportDoc
    from robocal.server.formats.report_doc import Outlier as OutlierDoc
    from robocal.solver.calibrate import Calibration
    from robocal.solver.screen import Outlier


def _note(text: str) -> None:
    """A fact the user should know, on stderr, the results going on."""
    print(f"robocal: note: {text}", file=sys.stderr)


def _campaign_only_with_database(args) -> None:
    """--campaign picks a campaign of a database; with a meas.csv it would be silently ignored."""
    from robocal.server.calibration import workflow

    if args.campaign is not None and not workflow.is_database(args.meas):
        raise workflow.DataError(
            f"{args.meas}: --campaign picks a campaign of a database (.db), not of a CSV file"
        )


# The arguments naming files a command reads, and those it writes (flag spellings for messages).
READS = ("meas", "cell", "model", "poses", "targets", "check", "joints", "db", "check_poses")
WRITES = {"out": "--out", "model_out": "--model-out", "truth_out": "--truth-out"}
WRITES.update(recording="--recording", json="--json")


def refuse_overwriting(args) -> None:
    """ValueError naming both when a file a command writes is one it reads or writes already:
    `calibrate meas.csv --out meas.csv` replaced the campaign with the model, `predict model.json
    meas.csv --out meas.csv` with the predictions, `diagnose --out r.json --model-out r.json`
    the report with the model, each said 'written' as if all were well."""
    seen: dict[Path, str] = {}
    for name in READS:
        path = getattr(args, name, None)
        if isinstance(path, str) and path and "://" not in path:
            seen.setdefault(Path(path).resolve(), f"the {name.replace('_', ' ')} file it reads")
    for name, flag in WRITES.items():
        path = getattr(args, name, None)
        if not isinstance(path, str) or not path:
            continue
        key = Path(path).resolve()
        if key in seen:
            raise ValueError(
                f"{flag} {path} is {seen[key]}: it would be overwritten; write to another file"
            )
        seen[key] = f"{flag}'s file too"


def _number(text: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None


def _integer(text: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number") from None


def _nonnegative(text: str) -> float:
    v = _number(text)
    if not np.isfinite(v) or v < 0:
        raise argparse.ArgumentTypeError(f"{text!r} is not a finite number >= 0")
    return v


def _positive(text: str) -> float:
    v = _number(text)
    if not np.isfinite(v) or v <= 0:
        raise argparse.ArgumentTypeError(f"{text!r} is not a finite number > 0")
    return v


def _rate(text: str) -> float:
    """A probability per reading: 1 would lose every reading."""
    v = _nonnegative(text)
    if v >= 1:
        raise argparse.ArgumentTypeError(f"{text!r} is not a rate from 0 up to (not including) 1")
    return v


def _whole(lo: int, hi: int | None, what: str):
    """An argparse type: a whole number from lo to hi (None: no top), else `what` it must be."""

    def check(text: str) -> int:
        v = _integer(text)
        if v < lo or (hi is not None and v > hi):
            raise argparse.ArgumentTypeError(f"{text!r} is not {what}")
        return v

    return check


_nonnegative_int = _whole(0, None, "a whole number >= 0")


_positive_int = _whole(1, None, "a positive integer")


def _require_deployable(args) -> None:
    """Refuse a model its validation marks not deployable, unless --force (then warn)."""
    from robocal.server.calibration.validation import file_refusal

    why = file_refusal(args.model)
    if why and not args.force:
        from robocal.server.calibration.workflow import DataError

        raise DataError(f"{args.model}: {why}; --force to use it anyway")
    if why:
        print(f"robocal: warning: {args.model}: {why}", file=sys.stderr)


def _diagnose_to_files(cell, meas, meas_path, report_path, model_path, screen=True):
    """Run the diagnosis; write the report, its figures beside it and the extended model (the
    report, the figures' paths, the diagnosis and its final model returned)."""
    from robocal.server.calibration import workflow
    from robocal.server.cli.tables import console

    with console.status("diagnosing: cross-validating candidate effects...") as status:
        d, model = workflow.diagnose(
            cell, meas, log=lambda msg: status.update(msg.strip()), screen=screen
        )
    report, figures = workflow.write_diagnosis(
        d,
        model,
        Path(report_path),
        {"file": Path(meas_path).name, "poses": meas.n_poses, "readings": meas.n_readings},
        model_path,
    )
    return report, figures, d, model


def _print_outliers(
    outliers: Sequence[Outlier | OutlierDoc] | None, skipped: str | None = None
) -> None:
    """The readings screened out as gross errors, one line each (None: screening was off)."""
    from robocal.server.cli.tables import console

    if outliers is None or skipped:
        console.print(
            "gross-outlier screening "
            + (f"skipped ({skipped})" if skipped else "off")
            + ": every reading used"
        )
        return
    if not outliers:
        console.print("no gross outlier among the readings")
        return
    console.print(
        f"{len(outliers)} reading{'s' if len(outliers) > 1 else ''} excluded as gross "
        "outliers (no plausible model fits them):"
    )
    for o in outliers:
        console.print(
            f"  pose {o.pose} target {o.target}: residual {o.residual_mm:.3f} mm ({o.evidence})"
        )


def _print_screening(cal: Calibration) -> None:
    screening = cal.screening
    _print_outliers(cal.outliers, screening.skipped if screening else None)


def _print_diagnosis(doc: ReportDoc) -> None:
    """The report as report.json has it (formats.report_doc), effect by effect."""
    from robocal.server.cli import tables
    from robocal.server.cli.tables import console
    from robocal.server.formats.blocks import Validation

    _print_outliers(doc.outliers)
    floor, base, final = doc.noise_floor_mm, doc.baseline, doc.final
    console.print(
        f"baseline (geometric) held-out RMS {base.holdout_rmse_mm:.4f} mm, "
        f"max {base.holdout_max_mm:.4f} mm; noise floor "
        + (f"{floor:.4f} mm" if floor else "unknown")
        + (f" (from the {doc.noise_floor_source})" if doc.noise_floor_source else "")
    )
    if not doc.effects:
        console.print("no effect beyond geometry pays off on held-out poses")
    for number, e in enumerate(doc.effects, start=1):  # as the figures are numbered
        console.print(
            f"[bold]effect {number}: {e.name}[/bold]"
            + (f" joint {e.joint}" if e.joint is not None else "")
            + (f" harmonic {e.harmonic}" if e.harmonic is not None else "")
            + (f" at {e.at_s:.0f} s" if e.at_s is not None else "")
            + f": {e.evidence}"
        )
        console.print("  " + tables.effect_parameters(e.parameters, e.uncertainty))
        lo, hi = e.holdout_gain_interval_mm or (float("nan"), float("nan"))
        console.print(
            f"  held-out gain {e.holdout_rmse_before_mm - e.holdout_rmse_after_mm:.4f} mm "
            f"(95% interval over poses {lo:.4f} to {hi:.4f} mm)"
        )
        if e.alternatives:
            console.print(
                "  [yellow]the data cannot tell it from:[/yellow] "
                + ", ".join(
                    f"{a.label} (held-out RMS {a.holdout_rmse_mm:.4f} mm)" for a in e.alternatives
                )
            )
    total = f" ({doc.seconds.total:.1f} s)" if doc.seconds is not None else ""
    console.print(
        f"final {final.model}: held-out RMS {final.holdout_rmse_mm:.4f} mm, "
        f"max {final.holdout_max_mm:.4f} mm{total}"
    )
    _print_unexplained(doc.unexplained)
    _print_extrapolation(doc.extrapolation)
    # the cause taken from the resamples, then any doubt they leave (once: the verdict's
    # warnings below carry them when there is a verdict)
    warned = Validation.of(doc.validation).warnings if doc.validation is not None else ()
    st = doc.stability
    for said in (st.agreed, st.half_way, *(st.held or ()), st.doubt) if st else ():
        if said and said not in warned:
            console.print(f"[yellow]{said}[/yellow]")
    if doc.validation is not None:  # the final model, judged as a calibration is
        for line in tables.validation_lines(Validation.of(doc.validation)):
            console.print(line)
    if doc.identified is not None:
        ident = doc.identified
        console.print("held fixed: " + tables.fixed_parameters(
            {f.parameter: f.why for f in ident.fixed}))  # fmt: skip
        console.print(tables.joints_table(ident))
        console.print(tables.frames_table(ident))
        console.print(tables.correlations(ident))


def _print_extrapolation(block: Extrapolation | None) -> None:
    """How far from its training poses the final model was tested, the effects refused there,
    and the joint ranges the data covers (where the model may be trusted)."""
    from robocal.server.cli.tables import console

    if block is None:
        return
    if block.folds:
        far = max(block.folds, key=lambda f: f.beyond_training_deg)
        worse = [f.test for f in block.folds if f.worse_only_in_geometric_span]
        console.print(
            f"tested off its training poses on {len(block.folds)} folds (trained on one side, "
            f"tested on the other), reaching up to {far.beyond_training_deg:.1f} deg beyond "
            f"them ({far.test}): "
            + (
                "no worse than geometry on any"
                if not worse
                else f"above geometry only inside geometry's own span on {', '.join(worse)}"
            )
        )
    else:
        console.print(
            "not tested off its training poses: too few poses to split, or no joint to split at moved 10 deg"
        )
    for r in block.refused:
        why = r.reason or f"worse than geometry on {'; '.join(r.worse_on)}"
        console.print(f"  refused {r.label}: {why}")
    ranges = ", ".join(
        f"q{j} {lo:.0f}..{hi:.0f}" for j, (lo, hi) in enumerate(block.joint_range_deg, start=1)
    )
    console.print(f"trusted within the joint ranges measured (deg): {ranges}")


def _print_unexplained(block: Unexplained | None) -> None:
    """What the final model leaves, and the covariates it follows most (strength 0..1)."""
    from robocal.server.cli.tables import console

    if block is None:
        return
    console.print(f"[bold]{block.reading}[/bold]")
    for c in block.covariates:
        console.print(f"  {c.strength:.2f}  {c.name}: {c.reading}")
    if block.per_pose_share is not None:
        console.print(f"  per pose: {block.per_pose_reading}")


def _data_arguments(p) -> None:
    """A campaign to read: a meas.csv or a database (with its campaign id), and the cell."""
    p.add_argument("meas", help="meas.csv, or a campaign database (.db file or URL)")
    p.add_argument(
        "--cell",
        help="cell.json (default: a database campaign's own cell, else the built-in IRB 2600 one)",
    )
    p.add_argument(
        "--campaign",
        type=_positive_int,
        help="campaign id when MEAS is a database (default: latest)",
    )


def _outlier_argument(p) -> None:
    p.add_argument(
        "--keep-outliers",
        action="store_true",
        help="use every reading: skip the screening for gross outliers (mis-locks, "
        "bumped SMRs) that otherwise excludes them and lists them",
    )


def _tolerance_argument(p) -> None:
    p.add_argument(
        "--tolerance-mm",
        type=_positive,
        metavar="T",
        help="the accuracy the application needs (mm): a model whose held-out error exceeds it "
        "is not deployable (default the cell's tolerance_mm; none: the verdict states the "
        "expected accuracy)",
    )


def _with_tolerance(cell, args):
    """The cell with --tolerance-mm, which wins over its cell.json's tolerance_mm."""
    if args.tolerance_mm is None:
        return cell
    from dataclasses import replace

    return replace(cell, tolerance_mm=args.tolerance_mm)


def _recording_arguments(parser, what: str) -> None:
    """--recording and --rerun-viewer: a rerun recording of what the command fits."""
    parser.add_argument("--recording", help=f"also write a rerun recording (.rrd) of {what}")
    parser.add_argument(
        "--rerun-viewer",
        metavar="URL",
        help="also stream the recording live to a running viewer, e.g. "
        "rerun+http://127.0.0.1:9876/proxy",
    )
