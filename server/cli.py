"""The `robocal` command line."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np


def cmd_simulate(args) -> None:
    from robocal.drivers.cell import TrackerSpec, VirtualCell
    from robocal.drivers.effects import make_effects

    from . import workflow
    from .formats.campaign_csv import write_campaign
    from .formats.model_json import write_json_atomic
    from .tables import console

    cell = workflow.load_cell(args.cell)
    vc = VirtualCell.random(
        cell.robot, cell.targets, seed=args.seed, tracker=TrackerSpec(**cell.tracker)
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


def _note(text: str) -> None:
    """A fact the user should know, on stderr, the results going on."""
    print(f"robocal: note: {text}", file=sys.stderr)


def _held_out_data(args, cell):
    """The --held-out readings (None without it); DataError if they are not of the cell."""
    from . import workflow
    from .validation import data_mismatch

    if args.held_out is None:
        if args.held_out_campaign is not None:
            raise workflow.DataError(
                "--held-out-campaign picks a campaign of --held-out's database"
            )
        return None
    if args.held_out_campaign is not None and not workflow.is_database(args.held_out):
        raise workflow.DataError(
            f"{args.held_out}: --held-out-campaign picks a campaign of a database (.db), "
            "not of a CSV file"
        )
    same_file = Path(args.held_out).resolve() == Path(args.meas).resolve()
    if same_file and args.held_out_campaign == args.campaign:
        raise workflow.DataError(f"{args.held_out}: the held-out readings are the fitted ones")
    held_cell, hold = workflow.load_data(args.held_out, args.cell, args.held_out_campaign)
    why = data_mismatch(cell.robot, list(cell.targets), held_cell)
    if why:
        raise workflow.DataError(f"{args.held_out}: {why}")
    return hold


def _campaign_only_with_database(args) -> None:
    """--campaign picks a campaign of a database; with a meas.csv it would be silently ignored."""
    from . import workflow

    if args.campaign is not None and not workflow.is_database(args.meas):
        raise workflow.DataError(
            f"{args.meas}: --campaign picks a campaign of a database (.db), not of a CSV file"
        )


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
    v = _nonnegative(text)
    if v == 0:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number > 0")
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
_port = _whole(0, 65535, "a TCP port (0 to 65535)")
_directions = _whole(1, 6, "a count of directions from 1 to 6")


def _fraction(text: str) -> float:
    v = _nonnegative(text)
    if v > 1:
        raise argparse.ArgumentTypeError(f"{text!r} is not a fraction between 0 and 1")
    return v


def cmd_calibrate(args) -> None:
    from robocal.solver.calibrate import parse_method

    from . import tables, workflow
    from .formats.model_json import write_model
    from .tables import console

    _campaign_only_with_database(args)
    if args.recording:  # refused now, not after the calibration
        from .formats.files import check_writable

        check_writable(args.recording)
    cell, meas = workflow.load_data(args.meas, args.cell, args.campaign, note=_note)
    cell = _with_tolerance(cell, args)
    hold = _held_out_data(args, cell)
    parse_method(args.method, meas.target_names)
    cal = workflow.run_method(cell, meas, args.method, qp=args.qp, screening=not args.keep_outliers)
    model = workflow.model_file(cal, cell, meas, data_path=args.meas)
    if hold is not None:  # the separate validation figure beside the leave-one-out one
        from .validation import held_out_errors

        model.meta.setdefault("validation", {})["held_out"] = {
            "file": Path(args.held_out).name,
            **({"campaign_id": args.held_out_campaign} if args.held_out_campaign else {}),
            **held_out_errors(model, hold),
        }
    write_model(args.out, model)
    if args.recording:
        from .recording import record_calibration

        record_calibration(
            args.recording,
            cell=cell,
            meas=meas,
            calibration=cal,
            held_out=hold,
            viewer_url=args.rerun_viewer,
        )
    fit = model.meta["fit"]
    console.print(
        f"{args.method} on {meas.n_poses} poses, {meas.n_readings} readings "
        f"in {cal.seconds * 1000:.0f} ms"
    )
    _print_screening(cal)
    if "held_out" in model.meta.get("validation", {}):  # the held-out figure is the headline
        console.print(tables.held_out_line(model.meta["validation"]["held_out"]))
    for line in tables.validation_lines(model.verdict):
        console.print(line)
    console.print("held fixed: " + tables.fixed_parameters(cal.fixed))
    console.print(tables.identified_geometry(cal.robot, cell.robot, model.meta["uncertainty"]))
    if "identified" in model.meta:
        console.print(tables.frames_table(model.meta["identified"]))
        console.print(tables.correlations(model.meta["identified"]))
    else:
        console.print(tables.frame_errors(model.meta["uncertainty"], meas.target_names))
    console.print(
        f"condition number {cal.condition:.3g}; "
        + ", ".join(f"F_{k} {v:.4f} mm^2" for k, v in fit["F_mm2"].items())
        + f"; RMSE(phi) {fit['rmse_phi_mm']:.4f} mm; RMS {fit['rmse_mm']:.4f} mm"
    )
    if "history" in cal:  # minimax
        console.print(
            f"SQP ({cal.qp} QP): {cal.nit} iterations, "
            f"{cal.qp_iterations} QP iterations, max F_i "
            f"{cal.history[0]:.5f} -> {cal.history[-1]:.5f} mm^2 ({cal.message})"
        )
    console.print(
        f"model written to {args.out}"
        + (f", rerun recording to {args.recording}" if args.recording else "")
    )
    _warn_undeployable(model.verdict, args.out)


def _warn_undeployable(verdict, path) -> None:
    """One line on stderr when a model's verdict says it is not to be deployed."""
    why = verdict.refusal()
    if why:
        print(f"robocal: warning: {path}: {why}", file=sys.stderr)


def cmd_predict(args) -> None:
    from . import workflow
    from .formats.campaign_csv import read_poses, write_predictions

    model = workflow.read_model(args.model)
    pose_ids, q, time_s, temp_c, prev_q = read_poses(args.poses, model.robot)
    try:
        xyz = workflow.model_predict(model, q, time_s, temp_c, prev_q)
    except workflow.DataError as e:
        raise workflow.DataError(f"{args.poses}: {e}") from None
    write_predictions(args.out, pose_ids, list(model.targets), xyz)
    # plain print, not rich's console: rich's import would be a fifth of predict's start
    print(f"predicted {len(pose_ids)} poses x {len(model.targets)} targets to {args.out}")


def _tcp(text: str) -> list[float]:
    from .compensation import parse_tcp

    try:
        return parse_tcp(text)
    except ValueError as e:
        raise argparse.ArgumentTypeError(str(e)) from None


def _require_deployable(args) -> None:
    """Refuse a model its validation marks not deployable, unless --force (then warn)."""
    from .validation import file_refusal

    why = file_refusal(args.model)
    if why and not args.force:
        from .workflow import DataError

        raise DataError(f"{args.model}: {why}; --force to use it anyway")
    if why:
        print(f"robocal: warning: {args.model}: {why}", file=sys.stderr)


def cmd_compensate(args) -> None:
    from .compensation import Limits, run

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


def cmd_check(args) -> int:
    from . import store
    from .check import EXIT_RECALIBRATE, run_check
    from .formats.model_json import write_json_atomic
    from .tables import console

    with store.open_database(args.db) as db:
        res = run_check(args.model, args.check, db)
    if args.out:
        write_json_atomic(args.out, res.to_json())
    console.print(f"{res.verdict} (check {res.history} of this model): {res.reason}")
    return EXIT_RECALIBRATE if res.verdict == "recalibrate" else 0


def cmd_evaluate(args) -> None:
    from . import tables, workflow
    from .formats.model_json import write_json_atomic
    from .tables import console

    model = workflow.read_model(args.model)
    _campaign_only_with_database(args)
    if workflow.is_database(args.meas):
        # The model's own robot reads the joints: the campaign's cell may differ in its targets.
        _, meas = workflow.load_data(args.meas, None, args.campaign, note=_note)
    else:
        from .formats.cell_json import Cell

        meas = workflow.load_campaign(args.meas, Cell(model.robot, model.targets, None, {}, None))
    try:
        res = workflow.evaluate(model, meas)
    except workflow.DataError as e:
        raise workflow.DataError(f"{args.meas}: {e}") from None
    from .validation import absurd_errors

    why = absurd_errors(res, model.verdict)
    if why and not args.force:
        raise workflow.DataError(f"{args.meas}: {why}; --force to evaluate anyway")
    if why:
        print(f"robocal: warning: {args.meas}: {why}", file=sys.stderr)
    if "nominal" in res:
        console.print(
            tables.accuracy(
                res["nominal"], "Nominal model (base and SMRs fitted)", meas.target_names
            )
        )
    console.print(tables.accuracy(res["model"], f"Model {args.model}", meas.target_names))
    if "improvement_pct" in res:
        console.print(
            "improvement over nominal: "
            + ", ".join(
                f"{k} {v:.1f}%" for k, v in res["improvement_pct"].items() if np.isfinite(v)
            )
        )
    if args.json:
        write_json_atomic(args.json, res)


def cmd_compare(args) -> None:
    from . import tables, workflow
    from .formats.model_json import write_json_atomic
    from .tables import console

    _campaign_only_with_database(args)
    cell, meas = workflow.load_data(args.meas, args.cell, args.campaign, note=_note)
    rows = workflow.compare(cell, meas, screen=not args.keep_outliers)
    _print_screening(next(iter(rows.values()))[0])
    console.print(tables.table3(rows, meas.target_names))
    for label, (cal, _) in rows.items():
        if "history" in cal:  # minimax
            console.print(
                f"{label}: {cal.nit} SQP iterations, {cal.qp_iterations} QP "
                f"iterations, {cal.sqp_seconds * 1000:.1f} ms, final max F_i "
                f"{cal.F.max():.6f} mm^2"
            )
    worst = {k: max(acc["F"].values()) for k, (_, acc) in rows.items()}
    best = [k for k, v in worst.items() if v <= min(worst.values()) * (1 + 1e-9)]
    console.print(f"smallest max F_i: {', '.join(best)}")
    if args.json:
        write_json_atomic(
            args.json,
            {
                k: {
                    "F": acc["F"],
                    "rmse_phi": acc["rmse_phi"],
                    "accuracy": acc,
                    "seconds": cal.seconds,
                }
                for k, (cal, acc) in rows.items()
            },
        )


def cmd_diagnose(args) -> None:
    from . import workflow
    from .tables import console

    _campaign_only_with_database(args)
    cell, meas = workflow.load_data(args.meas, args.cell, args.campaign, note=_note)
    cell = _with_tolerance(cell, args)
    report, figures, _ = _diagnose_to_files(
        cell, meas, args.meas, args.out, args.model_out, screen=not args.keep_outliers
    )
    _print_diagnosis(report)
    console.print(
        f"report written to {args.out}"
        + (f", model to {args.model_out}" if args.model_out else "")
        + "".join(f", figure {p}" for p in figures)
    )


def _diagnose_to_files(cell, meas, meas_path, report_path, model_path, screen=True):
    """Run the diagnosis; write the report, its figures beside it and the extended model."""
    from . import workflow
    from .tables import console

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
    return report, figures, d


def _print_outliers(outliers, skipped=None) -> None:
    """The readings screened out as gross errors, one line each (None: screening was off)."""
    from .tables import console

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
            f"  pose {o['pose']} target {o['target']}: residual {o['residual_mm']:.3f} mm "
            f"({o['evidence']})"
        )


def _print_screening(cal) -> None:
    screening = cal.get("screening")
    _print_outliers(cal.get("outliers"), screening.skipped if screening else None)


def _print_diagnosis(report) -> None:
    from . import tables
    from .tables import console

    _print_outliers(report.get("outliers"))
    floor = report["noise_floor_mm"]
    console.print(
        f"baseline (geometric) held-out RMS {report['baseline']['holdout_rmse_mm']:.4f} mm, "
        f"max {report['baseline']['holdout_max_mm']:.4f} mm; noise floor "
        + (f"{floor:.4f} mm" if floor else "unknown")
        + (
            f" (from the {report['noise_floor_source']})"
            if report.get("noise_floor_source")
            else ""
        )
    )
    if not report["effects"]:
        console.print("no effect beyond geometry pays off on held-out poses")
    for number, e in enumerate(report["effects"], start=1):  # as the figures are numbered
        console.print(
            f"[bold]effect {number}: {e['name']}[/bold]"
            + (f" joint {e['joint']}" if "joint" in e else "")
            + (f" harmonic {e['harmonic']}" if "harmonic" in e else "")
            + (f" at {e['at_s']:.0f} s" if "at_s" in e else "")
            + f": {e['evidence']}"
        )
        console.print("  " + tables.effect_parameters(e["parameters"], e.get("uncertainty")))
        lo, hi = e["holdout_gain_interval_mm"]
        console.print(
            f"  held-out gain {e['holdout_rmse_before_mm'] - e['holdout_rmse_after_mm']:.4f} mm "
            f"(95% interval over poses {lo:.4f} to {hi:.4f} mm)"
        )
        if e["alternatives"]:
            console.print(
                "  [yellow]the data cannot tell it from:[/yellow] "
                + ", ".join(
                    f"{a['label']} (held-out RMS {a['holdout_rmse_mm']:.4f} mm)"
                    for a in e["alternatives"]
                )
            )
    console.print(
        f"final {report['final']['model']}: held-out RMS {report['final']['holdout_rmse_mm']:.4f} mm, "
        f"max {report['final']['holdout_max_mm']:.4f} mm ({report['seconds']['total']:.1f} s)"
    )
    _print_unexplained(report.get("unexplained"))
    doubt = (report.get("stability") or {}).get("doubt")
    if doubt:
        console.print(f"[yellow]{doubt}[/yellow]")
    if "validation" in report:  # the final model, judged as a calibration is
        from .formats.verdict import Verdict

        for line in tables.validation_lines(Verdict.of(report["validation"])):
            console.print(line)
    if "identified" in report:
        ident = report["identified"]
        console.print("held fixed: " + tables.fixed_parameters(
            {f["parameter"]: f["why"] for f in ident["fixed"]}))  # fmt: skip
        console.print(tables.joints_table(ident))
        console.print(tables.frames_table(ident))
        console.print(tables.correlations(ident))


def _print_unexplained(block) -> None:
    """What the final model leaves, and the covariates it follows most (strength 0..1)."""
    from .tables import console

    if not block:
        return
    console.print(f"[bold]{block['reading']}[/bold]")
    for c in block["covariates"]:
        console.print(f"  {c['strength']:.2f}  {c['name']}: {c['reading']}")
    if "per_pose_share" in block:
        console.print(f"  per pose: {block['per_pose_reading']}")


def cmd_acquire(args) -> None:
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    from . import workflow
    from .acquire import AcquireOptions, acquire
    from .tables import console

    cell = workflow.load_cell(args.cell)
    if args.verify:
        return _verify(args, cell)
    opts = AcquireOptions(
        poses=args.poses,
        seed=args.seed,
        name=args.name,
        settle=args.settle,
        pause_s=args.pause,
        order=args.order,
        choose_from=args.choose_from,
        beam_break_rate=args.beam_break_rate,
        effects=tuple(args.effect),
    )
    with Progress(
        TextColumn("{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        console=console,
        transient=True,
    ) as progress:
        summary = acquire(args.db, cell, opts, progress=progress, reset=args.reset)
    if summary["resumed_at"] is not None:
        console.print(
            f"resumed campaign {summary['campaign']} ({summary['name']}) at pose "
            f"{summary['resumed_at'] + 1}"
        )
    locked = summary["locked_without_search_after_10"]
    console.print(
        f"campaign {summary['campaign']} {summary['state']}: {summary['measured_poses']} poses "
        f"measured now, {summary['readings']} readings, {summary['missing']} missing, "
        f"{summary['beam_breaks']} beam breaks"
        + (
            f"; {'simulated ' if summary.get('simulated', True) else ''}campaign time "
            f"{summary['campaign_s'] / 60:.1f} min"
            if summary["campaign_s"] is not None
            else ""
        )
        + (
            f"; locked without search after pose 10: {100 * locked:.1f}%"
            if locked is not None
            else ""
        )
    )
    console.print(
        f"stored in {args.db}; calibrate with: robocal calibrate {args.db} "
        f"--campaign {summary['campaign']}"
    )


def _verify(args, cell) -> None:
    """`acquire --verify model.json`: the ISO 9283 run before and after compensation."""
    from . import verification
    from .tables import console, verification_table

    opts = verification.VerifyOptions(
        cycles=args.cycles,
        directions=args.directions,
        points_path=args.points,
        side_mm=args.side,
        seed=args.seed,
        name=args.name or "verify",
        effects=tuple(args.effect),
        pause_s=args.pause,
    )
    with console.status("verifying: nominal joints, then compensated ones..."):
        report = verification.verify(args.db, cell, args.verify, opts)
    verification.write(report, args.out)
    console.print(verification_table(report))
    written = [args.out]
    if args.certificate:
        from .certificate import write_certificate

        write_certificate(report, args.certificate)
        written.append(args.certificate)
    console.print(f"wrote {', '.join(written)}")


def cmd_serve(args) -> None:
    settings = _settings(args)
    from . import store
    from .app import CannotListen, serve

    store.open_database(settings.database).close()  # a wrong --db: one line, before listening
    try:
        serve(settings)
    except CannotListen as e:
        raise SystemExit(f"robocal: error: {e}") from None


def cmd_token(args) -> None:
    from .security import reset_token

    settings = _settings(args, make_folder=args.action == "reset")
    path = settings.token_file
    if args.action == "reset":
        token = reset_token(path)
        print(token)
        print(
            f"robocal: a new API token (shown once, keep it); its hash is in {path}. The old "
            "token stops working at once, a running service included (it reads the file on "
            "each request): give the new one to every client and the page",
            file=sys.stderr,
        )
    elif path.exists():
        print(
            f"the token itself is kept nowhere, only its hash, in {path}; "
            f"`robocal token reset{' --data-dir ' + str(settings.data_dir) if args.data_dir else ''}`"
            " makes and prints a new one"
        )
    else:
        print(
            f"no token yet ({path} is absent): `robocal serve` makes one at its first start, "
            "or `robocal token reset` now"
        )


def _settings(args, make_folder: bool = True):
    """The service's settings: ROBOCAL_* variables, overridden by the options given; its data
    folder made (refused in one line if it is a file)."""
    from . import workflow
    from .settings import Settings

    overrides = {
        k: v
        for k, v in (
            ("database", args.db),
            ("host", args.host),
            ("port", args.port),
            ("data_dir", args.data_dir),
        )
        if v is not None
    }
    settings = Settings(**overrides)
    if settings.data_dir.exists() and not settings.data_dir.is_dir():
        raise workflow.DataError(f"{settings.data_dir}: the data folder is a file, not a folder")
    if make_folder:
        settings.data_dir.mkdir(parents=True, exist_ok=True)
    return settings


def cmd_demo(args) -> None:
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn

    from . import tables, workflow
    from .acquire import AcquireOptions, acquire
    from .formats.model_json import write_model
    from .tables import console

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    db = out / "robocal.db"
    for f in out.glob("robocal.db*"):  # a fresh campaign each run
        f.unlink()
    cell = workflow.load_cell(None)
    opts = AcquireOptions(
        poses=args.poses + args.holdout, seed=args.seed, name="demo", effects=tuple(args.effect)
    )
    console.print(
        f"acquiring {opts.poses} poses on the simulated IRB 2600 cell (tracker and "
        f"controller on 127.0.0.1, virtual clock; hidden effects: "
        f"{', '.join(args.effect) or 'none'}) into {db}"
    )
    with Progress(
        TextColumn("{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        console=console,
        transient=True,
    ) as progress:
        summary = acquire(db, cell, opts, progress=progress)
    console.print(
        f"campaign done: {summary['readings']} readings, simulated campaign time "
        f"{summary['campaign_s'] / 60:.1f} min"
    )
    cell, meas = workflow.load_data(db)
    cal_meas = meas.subset(np.arange(args.poses))
    hold = meas.subset(np.arange(args.poses, meas.n_poses))
    rows = workflow.compare(cell, cal_meas)
    console.print(tables.table3(rows, cal_meas.target_names))
    cal, _ = rows["minimax"]
    model = workflow.model_file(cal, cell, cal_meas)
    write_model(out / "model.json", model)
    geo = workflow.evaluate(model, hold)
    report, figures, diagnosis = _diagnose_to_files(
        cell, cal_meas, db, out / "report.json", out / "model-extended.json"
    )
    _print_diagnosis(report)
    from .recording import record_calibration

    extended = workflow.read_model(out / "model-extended.json")
    record_calibration(  # "after" the final, extended model; the minimax one beside it
        out / "calibration.rrd",
        cell=cell,
        meas=cal_meas,
        calibration=cal,
        nominal=rows["nominal"][0],
        held_out=hold,
        diagnosis=diagnosis,
        extended=extended,
    )
    ext = workflow.evaluate(extended, hold)
    console.print(
        tables.accuracy(
            ext["model"], f"extended model on the {args.holdout} held-out poses", hold.target_names
        )
    )
    console.print(
        f"held-out RMS: nominal {geo['nominal']['rmse']:.4f} mm, minimax "
        f"{geo['model']['rmse']:.4f} mm, extended {ext['model']['rmse']:.4f} mm"
    )
    console.print(
        f"files in {out}: robocal.db (the campaign), model.json (minimax), "
        f"model-extended.json, report.json, calibration.rrd (open with `uv run rerun "
        f"{out / 'calibration.rrd'}`)" + "".join(f", {p.name}" for p in figures)
    )


def cmd_export(args) -> None:
    from .exports import export, format_for

    # plain print: the exports need numpy and the model code only, not rich
    fmt = format_for(args.format, args.out)
    _require_deployable(args)
    for line in export(args.model, fmt, args.out, args.joints, args.targets):
        print(line)


def cmd_schema(args) -> None:
    # The committed file (tests keep it equal to the model's): no pydantic import to print it.
    folder = Path(__file__).parent / "formats" / "schema"
    sys.stdout.write((folder / f"{args.file}.schema.json").read_text(encoding="utf-8"))


def cmd_bench(args) -> None:
    if args.what == "diagnose":
        from .bench.diagnose import run_diagnose_bench

        result = run_diagnose_bench(
            quick=args.quick,
            effect_cases=args.cases,
            clean_cases=args.clean,
            sizes=args.poses,
            workers=args.workers,
            split_cases=args.split_cases,
            real=() if args.quick else _real_campaigns(),
        )
    elif args.what == "outliers":
        from .bench.screen import run_screen_bench

        result = run_screen_bench()
    elif args.what == "service":
        from .bench.service import run_service_bench

        result = run_service_bench()
    elif args.what == "startup":
        from .bench.startup import run_startup_bench

        result = run_startup_bench(repeats=args.repeats)
    elif args.what == "compensate":
        from .bench.compensate import run_compensate_bench

        result = run_compensate_bench()
    elif args.what == "verify":
        from .bench.verify import run_verify_bench

        result = run_verify_bench()
    elif args.what == "acquire":
        from .bench.acquire import run_acquire_bench

        result = run_acquire_bench()
    elif args.what == "recording":
        from .bench.recording import run_recording_bench

        result = run_recording_bench()
    elif args.what == "check":
        from .bench.check import run_check_bench

        result = run_check_bench(clean=args.clean or 70)
    elif args.what == "validation":
        from .bench import validation as bench_validation

        result = bench_validation.run(20, "minimax", _real_campaigns())
    else:
        from .bench.solver import run_solver_bench

        result = run_solver_bench(
            sizes=args.sizes, reference=not args.no_reference, reference_max=args.reference_max
        )
    print(json.dumps(result, indent=2))


def _real_campaigns() -> list[Path]:
    """The real campaigns beside a checkout (../shared/data/real), when they are there."""
    real = Path(__file__).resolve().parents[2] / "shared" / "data" / "real"
    return sorted(p for p in real.glob("*") if p.is_dir())


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


class Parser(argparse.ArgumentParser):
    """argparse, but a mistake is one line (not the usage block), with a "did you mean"."""

    def error(self, message: str):
        import difflib
        import re

        m = re.search(r"invalid choice: '([^']*)' \(choose from (.*)\)", message)
        if m:
            choices = [c.strip(" '") for c in m.group(2).split(",")]
            close = difflib.get_close_matches(m.group(1), choices, n=1)
            if close:
                message += f"; did you mean {close[0]!r}?"
        elif message.startswith("unrecognized arguments:"):
            known = self._option_strings()
            for word in message.split(":", 1)[1].split():
                close = difflib.get_close_matches(word.split("=")[0], known, n=1)
                if word.startswith("--") and close:
                    message += f"; {word}: did you mean {close[0]}?"
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")

    def _option_strings(self) -> list[str]:
        """Every long option of this parser and of its commands."""
        out = []
        for action in self._actions:
            out += [o for o in action.option_strings if o.startswith("--")]
            if isinstance(action, argparse._SubParsersAction):
                for sub in action.choices.values():
                    out += sub._option_strings()
        return sorted(set(out))


def build_parser() -> argparse.ArgumentParser:
    p = Parser(prog="robocal", description="Robot calibration with a laser tracker.")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND", help="what to do")

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

    c = sub.add_parser("calibrate", help="identify a model from a campaign")
    _data_arguments(c)
    c.add_argument(
        "--method",
        default="minimax",
        help="minimax (default), ls-sum, ls-single:TARGET (one SMR, default the first), ls-pose",
    )
    c.add_argument(
        "--qp",
        choices=("primal-dual", "exact"),
        default="primal-dual",
        help="minimax's QP subsolver: the paper's primal-dual method or Clarabel",
    )
    c.add_argument("--out", default="model.json", help="model.json to write (default model.json)")
    c.add_argument(
        "--held-out",
        metavar="MEAS",
        help="readings of the same cell not to fit on (meas.csv or database): the model's error "
        "on them is printed first and kept in model.json; the recording shows them apart",
    )
    c.add_argument(
        "--held-out-campaign",
        type=int,
        metavar="N",
        help="the campaign of --held-out's database (default its latest)",
    )
    _outlier_argument(c)
    _tolerance_argument(c)
    c.add_argument("--recording", help="also write a rerun recording (.rrd) of the calibration")
    c.add_argument(
        "--rerun-viewer",
        metavar="URL",
        help="also stream the recording live to a running viewer, e.g. "
        "rerun+http://127.0.0.1:9876/proxy",
    )
    c.set_defaults(func=cmd_calibrate)

    pr = sub.add_parser("predict", help="SMR positions a model predicts for poses")
    pr.add_argument("model", help="model.json (robocal calibrate)")
    pr.add_argument("poses", help="poses.csv: pose, q1..qN [, time_s, temp_c] (deg)")
    pr.add_argument("--out", default="pred.csv", help="predictions to write (default pred.csv)")
    pr.set_defaults(func=cmd_predict)

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

    e = sub.add_parser("evaluate", help="accuracy of a model on measured data")
    e.add_argument("model", help="model.json (robocal calibrate)")
    e.add_argument("meas", help="meas.csv, or a campaign database (.db file or URL)")
    e.add_argument(
        "--campaign",
        type=_positive_int,
        help="campaign id when MEAS is a database (default: latest)",
    )
    e.add_argument("--json", help="also write the figures as JSON")
    e.add_argument(
        "--force", action="store_true", help="evaluate data whose errors say another cell"
    )
    e.set_defaults(func=cmd_evaluate)

    ck = sub.add_parser(
        "check",
        help="quick check of a deployed model: ok, watch or recalibrate (exit 3), over its history",
    )
    ck.add_argument("model", help="model.json (robocal calibrate or diagnose)")
    ck.add_argument("check", help="check.csv: a meas.csv of the few poses measured every check")
    ck.add_argument(
        "--db", default="robocal.db", help="database of the checks' history (file or URL)"
    )
    ck.add_argument("--out", help="write check.json here")
    ck.set_defaults(func=cmd_check)

    co = sub.add_parser("compare", help="every method side by side (the paper's Table 3)")
    _data_arguments(co)
    co.add_argument("--json", help="also write the figures as JSON")
    _outlier_argument(co)
    co.set_defaults(func=cmd_compare)

    dg = sub.add_parser("diagnose", help="what the geometric model misses, named and modelled")
    _data_arguments(dg)
    dg.add_argument("--out", default="report.json", help="report (figures are written beside it)")
    dg.add_argument("--model-out", help="the final, extended model.json")
    _outlier_argument(dg)
    _tolerance_argument(dg)
    dg.set_defaults(func=cmd_diagnose)

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
        "--poses", type=_positive_int, default=100, help="poses to measure (default 100)"
    )
    aq.add_argument(
        "--seed", type=_nonnegative_int, default=0, help="random seed of the poses (and the cell)"
    )
    aq.add_argument("--name", help="campaign name; an unfinished campaign of that name is resumed")
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
    aq.add_argument("--out", default="verification.json", help="the verification's figures")
    aq.add_argument("--certificate", help="also write the accuracy certificate (HTML) here")
    aq.add_argument(
        "--reset",
        action="store_true",
        help="resume an e-stopped campaign (after the cell was checked)",
    )
    aq.set_defaults(func=cmd_acquire)

    sv = sub.add_parser(
        "serve", help="the workstation service (REST API), on 127.0.0.1 unless told"
    )
    sv.add_argument("--db", help="database file or URL (default robocal.db, or ROBOCAL_DATABASE)")
    sv.add_argument("--host", help="address to listen on (default 127.0.0.1)")
    sv.add_argument("--port", type=_port, help="port (default 8000)")
    sv.add_argument(
        "--data-dir", help="models, recordings and the token hash (default robocal-data)"
    )
    sv.set_defaults(func=cmd_serve)

    tk = sub.add_parser(
        "token",
        help="the service's API token: reset makes a new one (the old one stops working), "
        "show says where its hash is kept",
    )
    tk.add_argument("action", choices=("reset", "show"), help="reset: a new token; show: where")
    tk.add_argument(
        "--data-dir",
        help="the service's data folder (default robocal-data, or ROBOCAL_DATA_DIR)",
    )
    tk.set_defaults(func=cmd_token, db=None, host=None, port=None)

    d = sub.add_parser("demo", help="simulate, calibrate with every method, evaluate held-out")
    d.add_argument("--out", default="robocal-demo", help="folder for the demo's files")
    d.add_argument(
        "--poses", type=_positive_int, default=100, help="poses to calibrate on (default 100)"
    )
    d.add_argument(
        "--holdout",
        type=_positive_int,
        default=50,
        help="further poses to evaluate the models on (default 50)",
    )
    d.add_argument("--seed", type=_nonnegative_int, default=1, help="random seed (default 1)")
    d.add_argument(
        "--effect",
        action="append",
        metavar="SPEC",
        help="hidden effects of the simulated arm (default: joint_compliance:2); "
        "see `simulate --help`",
    )
    d.set_defaults(func=cmd_demo)

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

    sc = sub.add_parser("schema", help="the JSON Schema of cell.json, model.json or report.json")
    sc.add_argument("file", choices=("cell", "model", "report"), help="which file's schema")
    sc.set_defaults(func=cmd_schema)

    b = sub.add_parser("bench", help="benchmarks printing JSON")
    b.add_argument(
        "what",
        choices=(
            "solver",
            "diagnose",
            "acquire",
            "service",
            "outliers",
            "startup",
            "compensate",
            "verify",
            "recording",
            "validation",
            "check",
        ),
        help="what to time (validation: the deployment guard's flags on healthy, small and "
        "real campaigns; check: quick checks' false alarms and delays to a change)",
    )
    b.add_argument(
        "--repeats",
        type=_positive_int,
        default=7,
        help="startup: runs of each command (median reported)",
    )
    b.add_argument(
        "--poses",
        type=_positive_int,
        nargs="+",
        default=[100, 1000],
        help="diagnose: sizes of the campaigns timed one at a time",
    )
    b.add_argument(
        "--quick",
        action="store_true",
        help="diagnose: a short run (10 effect cases, 10 clean campaigns)",
    )
    b.add_argument(
        "--cases", type=_positive_int, help="diagnose: effect cases of the suite (default 60)"
    )
    b.add_argument(
        "--clean",
        type=_positive_int,
        help="diagnose: clean campaigns (default 200); check: clean checks an arm (default 70)",
    )
    b.add_argument(
        "--split-cases",
        type=_nonnegative_int,
        help="diagnose: cases of the configuration-split suite (default 45, quick 5; 0 skips it)",
    )
    b.add_argument(
        "--workers", type=_positive_int, default=2, help="diagnose: processes in the pool"
    )
    b.add_argument(
        "--sizes",
        type=_positive_int,
        nargs="+",
        default=[100, 1000, 10000],
        help="solver: pose counts timed (default 100 1000 10000)",
    )
    b.add_argument(
        "--no-reference", action="store_true", help="skip the finite-difference scipy reference"
    )
    b.add_argument(
        "--reference-max",
        type=_positive_int,
        default=10000,
        help="largest pose count for which to run the reference",
    )
    b.set_defaults(func=cmd_bench)
    return p


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    if args.command == "demo" and args.effect is None:
        args.effect = ["joint_compliance:2"]
    try:
        code = args.func(args)
    except KeyboardInterrupt:  # before or after any motion
        print("robocal: interrupted", file=sys.stderr)
        return 130
    except Exception as e:  # noqa: BLE001 - the expected kinds get one line; others propagate
        # imported here, not at the top: `robocal --help` must not wait for scipy and the store
        from robocal.solver.identifiability import NotIdentifiable

        from .acquire import AcquisitionFailed, Interrupted
        from .formats.errors import InputError
        from .store import StoreError
        from .workflow import DataError

        if isinstance(e, Interrupted):  # Ctrl-C of a run: the arm was e-stopped first
            print(f"robocal: {e}", file=sys.stderr)
            return 130
        if isinstance(e, (InputError, DataError, NotIdentifiable, AcquisitionFailed, StoreError)):
            print(f"robocal: error: {e}", file=sys.stderr)
            return 1
        if isinstance(e, FileNotFoundError):
            print(f"robocal: error: {e.filename}: no such file", file=sys.stderr)
            return 1
        if isinstance(e, OSError) and e.filename is not None:  # a folder, no permission...
            print(f"robocal: error: {e.filename}: {e.strerror or e}", file=sys.stderr)
            return 1
        if _is_settings_error(e):
            print(f"robocal: error: {_settings_error_line(e)}", file=sys.stderr)
            return 1
        if isinstance(e, ValueError):
            print(f"robocal: error: {e}", file=sys.stderr)
            return 1
        raise
    return code if isinstance(code, int) else 0


def _is_settings_error(e: Exception) -> bool:
    # pydantic is imported only if the settings were built: `robocal --help` stays light.
    pydantic = sys.modules.get("pydantic")
    return pydantic is not None and isinstance(e, pydantic.ValidationError)


def _settings_error_line(e) -> str:
    """A settings ValidationError (from ROBOCAL_* variables) as one line naming the setting."""
    first = e.errors()[0]
    name = ".".join(str(x) for x in first["loc"])
    more = f" (and {e.error_count() - 1} more)" if e.error_count() > 1 else ""
    return (
        f"setting {name!r} (ROBOCAL_{name.upper()}): {first['msg']}, "
        f"not {first.get('input')!r}{more}"
    )


if __name__ == "__main__":
    sys.exit(main())
