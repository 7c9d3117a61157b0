"""Human summaries of results as terminal tables."""

from __future__ import annotations

import sys
from typing import TYPE_CHECKING

import numpy as np
from rich.console import Console
from rich.table import Table

if TYPE_CHECKING:
    from robocal.server.fleet import Fleet
    from robocal.server.formats.blocks import HeldOut, Identified, Uncertainty, Validation
    from robocal.server.formats.verification_doc import VerificationDoc
    from robocal.solver.calibrate import Calibration
    from robocal.solver.metrics import Accuracy, Stats

# Wide enough for Table 3's eight columns when the output is a file or a pipe.
console = Console(highlight=False, width=None if sys.stdout.isatty() else 160)


def _f(v, digits=4) -> str:
    if v is None or not np.isfinite(v):
        return "-"
    return f"{v:.{digits}g}" if abs(v) >= 10**digits or abs(v) < 1e-3 else f"{v:.{digits}f}"


def table3(rows: dict[str, tuple[Calibration, Accuracy]], target_names) -> Table:
    """The paper's Table 3 (sum of squared errors per SMR, RMSE(phi)) plus AP/AO statistics."""
    t = Table(title="Methods side by side on the calibration data (the paper's Table 3)")
    t.add_column("")
    for label in rows:
        t.add_column(label, justify="right")
    for name in target_names:
        t.add_row(f"F_{name} / mm^2", *[_f(acc.F[name]) for _, acc in rows.values()])
    t.add_row(
        "max F_i / mm^2", *[_f(max(acc.F.values())) for _, acc in rows.values()], style="bold"
    )
    t.add_row("RMSE(phi) / mm", *[_f(acc.rmse_phi) for _, acc in rows.values()])
    t.add_row("AP mean / mm", *[_f(acc.ap.mean) for _, acc in rows.values()])
    t.add_row("AP std / mm", *[_f(acc.ap.std) for _, acc in rows.values()])
    t.add_row("AP max / mm", *[_f(acc.ap.max) for _, acc in rows.values()])
    accs = [acc for _, acc in rows.values()]
    if accs[0].ao_log is not None:
        # every method on the same data has an orientation when the first has one
        t.add_row("AO' mean / deg", *[_f(a.ao_log.mean if a.ao_log else None) for a in accs])
        t.add_row("AO' max / deg", *[_f(a.ao_log.max if a.ao_log else None) for a in accs])
        for c in "abc":
            t.add_row(
                f"AO {c} mean / deg",
                *[_f(a.ao_euler[c].mean if a.ao_euler else None) for a in accs],
            )
    t.add_row("time / ms", *[f"{cal.seconds * 1000:.0f}" for cal, _ in rows.values()])
    return t


def _row(s: Stats) -> list[str]:
    """A statistics row's cells: mean, std, max, rms."""
    return [_f(s.mean), _f(s.std), _f(s.max), _f(s.rms)]


def accuracy(acc: Accuracy, title: str, target_names) -> Table:
    """Positioning and orientation statistics of one model on one data set."""
    t = Table(title=title)
    for col in ("", "mean", "std", "max", "rms"):
        t.add_column(col, justify="right" if col else "left")
    for name in target_names:
        t.add_row(f"AP {name} / mm", *_row(acc.ap_per_target[name]))
    t.add_row("AP all / mm", *_row(acc.ap), style="bold")
    if acc.ao_euler is not None and acc.ao_log is not None:
        for c in "abc":
            t.add_row(f"AO {c} (Euler) / deg", *_row(acc.ao_euler[c]))
        t.add_row("AO' (log) / deg", *_row(acc.ao_log), style="bold")
    return t


def fixed_parameters(fixed: dict) -> str:
    return "; ".join(f"{k} ({v})" for k, v in fixed.items()) or "none"


def shrunk_parameters(shrunk: dict) -> str:
    """The shrunk parameters (name -> solver.identifiability.Shrunk) in a line."""
    return "; ".join(f"{k} ({s.share:.0%} from the data: {s.why})" for k, s in shrunk.items())


def plus_minus(v: float, se: float | None, sign: str = "") -> str:
    """A value with its standard error, both to the standard error's second significant digit."""
    if se is None or not np.isfinite(se):
        return _f(v)
    places = int(min(8, max(0, 1 - np.floor(np.log10(se))))) if se > 0 else 4
    return f"{v:{sign}.{places}f} ± {se:.{places}f}"


def identified_geometry(robot, nominal, uncertainty: Uncertainty) -> Table:
    """Each joint's identified parameters as change from nominal ± standard error ('fixed' where
    not identifiable), in mm and degrees."""
    se = uncertainty.standard_errors or {}
    t = Table(
        title="Identified geometry: change from nominal ± standard error "
        f"({uncertainty.estimator}; mm, deg)"
    )
    kinds = ("theta", "d", "a", "alpha", "beta")
    for col in ("joint",) + kinds:
        t.add_column(col, justify="right")
    names = robot.param_names()
    delta = robot.param_vector() - nominal.param_vector()
    by_name = {
        n: (np.degrees(v) if n.startswith(("theta", "alpha", "beta")) else v)
        for n, v in zip(names, delta)
    }
    for j in range(1, robot.n_joints + 1):
        cells = []
        for k in kinds:
            n = f"{k}{j}"
            cells.append(
                ""
                if n not in by_name
                else "fixed"
                if (s := se.get(n)) is None
                else plus_minus(by_name[n], s, "+")
            )
        t.add_row(str(j), *cells)
    return t


def frame_errors(uncertainty: Uncertainty, target_names) -> str:
    """One line: the base frame's and each SMR's standard errors."""
    se = uncertainty.standard_errors or {}

    def group(names, unit):
        return (
            "/".join("fixed" if se.get(n) is None else f"{se[n]:.2g}" for n in names) + f" {unit}"
        )

    smrs = "; ".join(f"{t} {group([f'{t}_{c}' for c in 'xyz'], 'mm')}" for t in target_names)
    return (
        "standard errors: base x/y/z "
        + group(["base_x", "base_y", "base_z"], "mm")
        + ", rz/ry/rx "
        + group(["base_rz", "base_ry", "base_rx"], "deg")
        + f"; SMRs x/y/z (flange frame) {smrs}"
    )


def effect_parameters(parameters: dict, uncertainty: dict | None) -> str:
    """An effect's parameters, each with ± its standard error where it has one."""
    out = []
    for k, v in parameters.items():
        se = (uncertainty or {}).get(k)
        if isinstance(v, (list, tuple)) and isinstance(se, (list, tuple)):
            out.append(f"{k} [" + ", ".join(plus_minus(a, b) for a, b in zip(v, se)) + "]")
        elif isinstance(v, (int, float)) and not isinstance(v, bool) and se is not None:
            out.append(f"{k} {plus_minus(v, se)}")
        else:
            out.append(f"{k} {v}")
    return ", ".join(out)


def verification_table(report: VerificationDoc) -> Table:
    """ISO 9283 figures per test point, before (nominal joints) and after compensation, mm."""
    t = Table(title=f"verification of {report.model.path} on {report.robot}")
    for col in ("point", "AP before", "AP after", "RP before", "RP after (-U/+U)",
                "vAP before", "vAP after"):  # fmt: skip
        t.add_column(col, justify="left" if col == "point" else "right")
    for b, a in zip(report.before.points, report.after.points):
        rp_u = (
            f" (-{a.RP_U_below_mm:.4f}/+{a.RP_U_above_mm:.4f})"
            if a.RP_U_below_mm is not None and a.RP_U_above_mm is not None
            else ""
        )
        t.add_row(
            b.point,
            *(f"{x:.4f}" for x in (b.AP_mm, a.AP_mm, b.RP_mm)),
            f"{a.RP_mm:.4f}{rp_u}",
            f"{b.vAP_mm:.4f}",
            f"{a.vAP_mm:.4f}",
        )
    for d, e in zip(report.before.distances, report.after.distances):
        t.add_row(
            "AD/RD " + "-".join(d.pair),
            f"{d.AD_mm:.4f}",
            f"{e.AD_mm:.4f}",
            f"{d.RD_mm:.4f}",
            f"{e.RD_mm:.4f}",
            "",
            "",
        )
    return t


def verification_decisions(report: VerificationDoc) -> list[str]:
    """One line per decision of a verification (AP against the tolerance, RP against the arm's
    stated repeatability), as ISO 14253-1's guard bands give it."""
    unc = report.uncertainty
    if unc is None:
        return []
    out = []
    for d, figure, against, given in (
        (unc.decision, "AP", "the tolerance", "tolerance_mm"),
        (unc.rp_decision, "RP", "the arm's stated repeatability", "repeatability_mm"),
    ):
        if d is not None and d.tolerance_mm is None:
            out.append(f"{figure}: no pass or fail (the cell gives no {given})")
        elif d is not None:
            out.append(
                f"{figure}: {d.verdict} against {against} {d.tolerance_mm:g} mm "
                "(ISO 14253-1 guard bands)"
            )
    return out


def joints_table(identified: Identified) -> Table:
    """Each joint's identified parameters from an `identified` block: change from nominal ±
    standard error ('fixed' where held), in mm and degrees."""
    kinds = ("theta", "d", "a", "alpha", "beta")
    t = Table(title="Identified geometry: change from nominal ± standard error (mm, deg)")
    for col in ("joint",) + kinds:
        t.add_column(col, justify="right")
    by_joint: dict[int, dict[str, str]] = {}
    for r in identified.rows:
        if r.group != "joint" or r.change is None or r.joint is None or r.kind is None:
            continue
        held = r.status == "held fixed"
        by_joint.setdefault(r.joint, {})[r.kind] = (
            "fixed" if held else plus_minus(r.change, r.standard_error, "+")
        )
    for j in sorted(by_joint):
        t.add_row(str(j), *(by_joint[j].get(k, "") for k in kinds))
    return t


def frames_table(identified: Identified) -> Table:
    """The base (tracker frame) and each SMR (flange frame), one coordinate a row: calibrated
    value ± standard error, and the change from the cell's nominal where it has one."""
    t = Table(title="Identified base and SMR frames (mm, deg)")
    for col in ("frame", "", "calibrated ± standard error", "change from nominal"):
        t.add_column(col, justify="right" if col.startswith(("cal", "change")) else "left")
    for r in identified.rows:
        if r.group == "joint":
            continue
        frame = "base (tracker)" if r.group == "base" else f"SMR {r.target} (flange)"
        value = (
            f"{_f(r.calibrated)} fixed"
            if r.status == "held fixed" or r.calibrated is None
            else plus_minus(r.calibrated, r.standard_error)
        )
        change = "" if r.change is None else f"{r.change:+.4f}"
        t.add_row(frame, f"{r.kind} / {r.unit}", value, change)
    return t


def correlations(identified: Identified) -> str:
    """One line: the strongest correlations between identified parameters."""
    return "strongest correlations: " + (
        ", ".join(f"{c.a}~{c.b} {c.r:+.3f}" for c in identified.correlations) or "none"
    )


def _mm(x) -> str:
    """A length in mm, "-" for none; past a metre in three significant digits."""
    return "-" if x is None else f"{x:.4f} mm" if abs(x) < 1000 else f"{x:.3g} mm"


def held_out_line(h: HeldOut) -> str:
    """The model's error on readings it was not fitted on (a file or campaign), beside the
    nominal model's on them."""
    where = h.file or f"campaign {h.campaign_id}"
    return (
        f"[bold]on held-out {where} ({h.poses} poses, {h.readings} readings): RMS "
        f"{_mm(h.rms_mm)}[/bold], max {_mm(h.max_mm)}; nominal RMS "
        f"{_mm(h.nominal_rms_mm)}"
        + (f"\n[bold red]warning[/bold red]: {h.warning}" if h.warning else "")
    )


def _holdout_kind(v: Validation) -> str:
    """How the held-out figure was had, in a few words: "leave-one-pose-out", "5-fold"."""
    how = v.holdout or "leave-one-pose-out"
    return how.split(" cross-validation")[0]


def validation_lines(v: Validation) -> list[str]:
    """The held-out figure (headline) beside the fit's, and the verdict: the accuracy to expect
    (within the tolerance, when one is given) or the reasons it is not deployable."""
    out = []
    if v.holdout_rms_mm is not None or v.fit_rms_mm is not None:
        out.append(
            f"[bold]held-out RMS {_mm(v.holdout_rms_mm)}[/bold] ({_holdout_kind(v)}, max "
            f"{_mm(v.holdout_max_mm)}); fit RMS {_mm(v.fit_rms_mm)}"
            + (f" (nominal {_mm(v.nominal_rms_mm)}" if v.nominal_rms_mm else "")
            + (
                f", {_mm(v.nominal_holdout_rms_mm)} held out"
                if v.nominal_rms_mm and v.nominal_holdout_rms_mm
                else ""
            )
            + (")" if v.nominal_rms_mm else "")
            + "; condition number "
            f"{_f(v.condition_number, 3)}; noise floor {_mm(v.noise_floor_mm)}"
            + (f" (from the {v.noise_floor_source})" if v.noise_floor_source else "")
        )
    if v.deployable:
        out.append(f"[green]deployable[/green]: {v.summary or 'no limit of the guard is broken'}")
    else:
        out.append("[bold red]NOT DEPLOYABLE[/bold red]:")
        out += [f"  - {r}" for r in v.reasons]
        if v.summary:
            out.append(f"  ({v.summary})")
    out += [f"[yellow]warning[/yellow]: {w}" for w in v.warnings]
    return out


def fleet(f: Fleet) -> Table:
    """The arms of one robot model: each arm's furthest parameter from the fleet (in units of
    its spread and own uncertainty) and its largest jump since its previous calibration."""
    limits = [p.limit for p in f.parameters if p.limit is not None]
    t = Table(
        title=f"Fleet of {f.robot_model}: {len(f.arms)} arms; flagged beyond |z| "
        + (f"{min(limits):.1f}-{max(limits):.1f}" if limits else "- (too few arms)")
        + f", jumps beyond {_f(f.jump_limit, 2)} (each {f.family_rate:.0%} false alarms a fleet)"
    )
    for col in ("arm", "calibrations", "job", "furthest", "z", "largest jump", "jump z", ""):
        t.add_column(col, justify="left" if col in ("arm", "furthest", "largest jump") else "right")
    for a in f.arms:
        far = max(a.parameters, key=lambda p: abs(p.z or 0.0), default=None)
        jumps = [p for p in a.parameters if p.jump_z is not None]
        big = max(jumps, key=lambda p: abs(p.jump_z or 0.0), default=None)
        verdict = ", ".join(
            w for w, on in (("OFF THE FLEET", a.flagged), ("JUMPED", a.jumped)) if on
        )
        t.add_row(
            a.arm,
            str(a.calibrations),
            str(a.job_id),
            far.parameter if far else "-",
            _f(far.z if far else None, 2),
            f"{big.parameter} {big.jump:+.4g}" if big and big.jump is not None else "-",
            _f(big.jump_z if big else None, 2),
            verdict or "ok",
            style="bold red" if verdict else None,
        )
    return t
