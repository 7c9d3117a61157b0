"""The accuracy certificate of a verification run: one self-contained HTML page (inline CSS,
plots as inline PNG), A4 when printed, naming the robot, the model, the instrument, the date and
the ISO 9283 figures before and after compensation."""

from __future__ import annotations

import base64
import io
from html import escape
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # files only: the workstation may have no display

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from robocal.server.formats.verification_doc import (  # noqa: E402
    Decision,
    PointFigures,
    RunFigures,
    VerificationDoc,
    VerificationUncertainty,
    VerifiedModel,
    VolumeMap,
)

CSS = """
body { font: 11pt/1.4 "DejaVu Sans", Arial, sans-serif; color: #111; max-width: 190mm;
       margin: 10mm auto; }
h1 { font-size: 18pt; margin: 0 0 2mm; } h2 { font-size: 13pt; margin: 6mm 0 2mm; }
table { border-collapse: collapse; width: 100%; margin: 2mm 0; }
th, td { border: 1px solid #999; padding: 1mm 2mm; text-align: right; }
th:first-child, td:first-child { text-align: left; }
th { background: #eee; } .id td { text-align: left; } .id td:first-child { width: 35mm; }
.verdict { font-size: 12pt; padding: 2mm 3mm; border: 2px solid #286; background: #efe; }
figure { margin: 3mm 0; text-align: center; } img { max-width: 100%; }
.note { font-size: 9pt; color: #444; }
.overdue { color: #a3333d; }
#uncertainty td { white-space: nowrap; }
@page { size: A4; margin: 12mm; }
@media print { body { margin: 0; } h2, table, figure { break-inside: avoid; } }
"""


def _png(fig) -> str:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110)
    plt.close(fig)
    return "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode()


def figure_ap_rp(report: VerificationDoc) -> str:
    """AP and RP per test point, before and after, on a log axis (mm)."""
    names = [p.point for p in report.before.points]
    x = np.arange(len(names))
    fig, axes = plt.subplots(1, 2, figsize=(9, 3.2), constrained_layout=True)
    for ax, key, title in ((axes[0], "AP_mm", "accuracy AP"), (axes[1], "RP_mm", "repeat. RP")):
        for shift, run, label in (
            (-0.2, report.before, "nominal joints"),
            (0.2, report.after, "compensated"),
        ):
            figures = [p.AP_mm if key == "AP_mm" else p.RP_mm for p in run.points]
            ax.bar(x + shift, figures, 0.4, label=label)
        if key == "AP_mm":  # the two runs differ by orders of magnitude; RP should not
            ax.set_yscale("log")
        ax.set_xticks(x, names)
        ax.set_ylabel("mm")
        ax.set_title(title)
        ax.grid(alpha=0.3, axis="y")
    fig.legend(*axes[0].get_legend_handles_labels(), loc="outside lower center", ncols=2)
    return _png(fig)


def figure_scatter(report: VerificationDoc) -> str:
    """Each attained position less its commanded one, x against y (µm), before and after."""
    fig, axes = plt.subplots(1, 2, figsize=(9, 3.6), constrained_layout=True)
    runs: tuple[tuple[RunFigures, str], ...] = (
        (report.before, "nominal joints"),
        (report.after, "compensated"),
    )
    for ax, (run, title) in zip(axes, runs):
        for p in run.points:
            d = 1e3 * (np.array(p.attained_mm) - np.array(p.commanded_mm))
            ax.scatter(d[:, 0], d[:, 1], s=12, label=p.point)
        ax.axhline(0, color="grey", lw=0.8)
        ax.axvline(0, color="grey", lw=0.8)
        ax.set_aspect("equal", adjustable="datalim")
        ax.set_xlabel("x error, µm")
        ax.set_ylabel("y error, µm")
        ax.set_title(f"attained - commanded, {title}")
        ax.grid(alpha=0.3)
    axes[1].legend(fontsize=7, loc="best")
    return _png(fig)


def figure_uncertainty_map(volume: VolumeMap) -> str:
    """U over the working volume: the map's positions in three slices of height, coloured by U."""
    xyz, u = np.asarray(volume.xyz_mm), np.asarray(volume.U_mm)
    edges = np.quantile(xyz[:, 2], [0, 1 / 3, 2 / 3, 1])
    fig, axes = plt.subplots(1, 3, figsize=(9, 3.3), constrained_layout=True, sharey=True)
    norm = plt.Normalize(float(u.min()), float(u.max()))
    for i, ax in enumerate(axes):
        band = (xyz[:, 2] >= edges[i]) & (xyz[:, 2] <= edges[i + 1])
        sc = ax.scatter(xyz[band, 0], xyz[band, 1], c=u[band], s=9, cmap="viridis", norm=norm)
        ax.set_title(f"z {edges[i]:.0f} to {edges[i + 1]:.0f} mm", fontsize=9)
        ax.set_xlabel("x, mm")
        ax.set_aspect("equal", adjustable="datalim")
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("y, mm")
    fig.colorbar(sc, ax=axes, label="U (95 %), mm", shrink=0.85)
    return _png(fig)


def verdict_sentence(dec: Decision | None, figure: str, against: str, give: str) -> str:
    """The decision's sentence: PASS / FAIL / NOT DECIDED of `figure` (AP, RP) against the
    tolerance (`against` names it), or why there is none (`give` says where to state it)."""
    if dec is None:
        return ""
    tol, verdict = dec.tolerance_mm, dec.verdict
    if verdict == "no tolerance":
        return f"No {against} given ({give}): no pass or fail on {figure}."
    late = dec.tracker_overdue
    return {
        "pass": f"<b>{figure} PASS</b> against the {against} {tol:g} mm: every {figure} plus "
        "its U is within it.",
        "fail": f"<b>{figure} FAIL</b> against the {against} {tol:g} mm: an {figure} less its U "
        "is beyond it.",
        "not decided": f"<b>{figure} NOT DECIDED</b> against the {against} {tol:g} mm: "
        + (
            f"the tracker's calibration was due {escape(str(late))}."
            if late
            else f"a point's {figure} less its U is within it, but not plus its U."
        ),
    }[verdict]


def _rp(q: PointFigures) -> str:
    """An RP with its U below and above, as the certificate prints it."""
    if q.RP_U_below_mm is None or q.RP_U_above_mm is None:
        return f"{q.RP_mm:.4f}"
    return f"{q.RP_mm:.4f} −{q.RP_U_below_mm:.4f} / +{q.RP_U_above_mm:.4f}"


def uncertainty_section(report: VerificationDoc) -> tuple[str, str]:
    """The verdicts' sentences on the tolerance (AP) and the arm's repeatability (RP), and the
    uncertainty section's HTML (the model's U "-" without its figures: a model written before
    them, or one whose time or temperature terms the run's readings could not feed, which its
    note then says)."""
    unc = report.uncertainty or VerificationUncertainty()
    dec, rp_dec = unc.decision, unc.rp_decision
    said = verdict_sentence(dec, "AP", "tolerance", "the cell's tolerance_mm or the model's")
    said += " " + verdict_sentence(
        rp_dec, "RP", "arm's stated repeatability", "the cell's repeatability_mm"
    )
    model = unc.model
    rows = []
    for i, q in enumerate(report.after.points):
        rows.append(
            (
                q.point,
                f"{q.AP_mm:.4f} ± {q.AP_U_mm:.4f}" if q.AP_U_mm is not None else f"{q.AP_mm:.4f}",
                _rp(q),
                f"{model.model_U_mm[i]:.4f}" if model else "-",
                f"{model.reading_U_mm[i]:.4f}" if model else "-",
            )
        )
    head = ["point", "AP after ± U (mm)", "RP after −U / +U (mm)", "model U (mm)"]
    html = '<h2>Uncertainty and decision</h2><div id="uncertainty">' + _table(
        head + ["a reading's U (mm)"], rows
    )
    html += "</div>"
    if model and model.map:
        html += (
            '<figure><img alt="U over the working volume" '
            f'src="{figure_uncertainty_map(model.map)}"></figure>'
        )
    notes = [unc.ap_u, unc.rp_u or "", unc.model_note or "", unc.compensation_note or ""]
    if model:
        notes.append(
            f"Model U: the radius holding the arm's position error with "
            f"{100 * model.coverage:.0f} % probability (k about {np.median(model.k):.1f}), "
            "from the parameters' covariance (an extended model's coefficients included) and "
            "the error the model leaves unexplained (a joint "
            f"scatter of {model.joint_scatter_deg:.4f} deg RMS); a reading's U adds the "
            "tracker's specification."
        )
    elif not unc.model_note:
        notes.append("The model keeps no position uncertainty: its U is not stated.")
    for d in (dec, rp_dec):
        if d is not None:
            notes.append("Decision rule: " + d.rule + ".")
    # each note a sentence: the methods' texts are stated without their full stop
    html += "".join(
        f'<p class="note">{escape(n if n.endswith(".") else n + ".")}</p>' for n in notes if n
    )
    return said.strip(), html


def _rows(rows) -> str:
    return "".join(
        "<tr>" + "".join(f"<td>{escape(str(c))}</td>" for c in r) + "</tr>" for r in rows
    )


def _table(head, rows, cls="") -> str:
    th = "".join(f"<th>{escape(h)}</th>" for h in head)
    tr = f"<tr>{th}</tr>" if head else ""
    return f'<table class="{cls}">{tr}{_rows(rows)}</table>'


def _rp_span(run: RunFigures) -> str:
    """The worst point's RP interval: [RP - U-, RP + U+]."""
    q = max(run.points, key=lambda p: p.RP_mm)
    return f"{q.RP_mm - (q.RP_U_below_mm or 0.0):.4f} to {q.RP_mm + (q.RP_U_above_mm or 0.0):.4f}"


def holdout_rms(model: VerifiedModel) -> float | None:
    """The model's held-out RMS (mm) as its diagnosis stated it, else as its validation did
    (a calibration's leave-one-pose-out figure); None if neither did."""
    return model.quote().holdout_rms_mm()


def render(report: VerificationDoc) -> str:
    """The certificate's HTML."""
    b, a = report.before, report.after
    inst = report.instrument
    trace = [
        ("Tracker serial", inst.serial or "not given"),
        (
            "Tracker calibration",
            f"certificate {inst.certificate_id or 'not given'}, due "
            f"{inst.certificate_due or 'not given'}"
            + (" - OVERDUE at this run" if report.tracker_overdue else ""),
        ),
        (
            "SMR ids",
            ", ".join(f"{k} {v}" for k, v in (inst.smr_ids or {}).items()) or "not given",
        ),
    ]
    rms = holdout_rms(report.model)
    ident = [
        ("Robot", report.robot),
        ("Model", report.model.path),
        ("Model SHA-256", report.model.sha256),
        ("Model held-out RMS", "-" if rms is None else f"{rms:.4f} mm"),
        ("Instrument", inst.description()),
        *trace,
        ("Cell", "simulated" if report.simulated else "real devices"),
        ("Date (UTC)", report.date),
        ("Measured point", f"SMR {report.smr}"),
        (
            "Procedure",
            f"ISO 9283 test points {', '.join(report.points)}; {report.cycles} cycles x "
            f"{report.directions} approach directions ({report.approach_mm:g} mm out)",
        ),
    ]
    summary = [
        ("AP, worst point (mm)", f"{b.AP_max_mm:.4f}", f"{a.AP_max_mm:.4f}"),
        ("RP, worst point (mm)", f"{b.RP_max_mm:.4f}", f"{a.RP_max_mm:.4f}"),
        *(
            [("RP, worst point, 95 % interval (mm)", _rp_span(b), _rp_span(a))]
            if a.points[0].RP_U_above_mm is not None
            else []
        ),
    ]
    points = [
        (
            p.point,
            *(f"{v:.1f}" for v in p.commanded_mm),
            f"{p.AP_mm:.4f}",
            f"{q.AP_mm:.4f}",
            f"{p.RP_mm:.4f}",
            f"{q.RP_mm:.4f}",
            f"{p.vAP_mm:.4f}",
            f"{q.vAP_mm:.4f}",
        )
        for p, q in zip(b.points, a.points)
    ]
    distances = [
        (
            " - ".join(p.pair),
            f"{p.AD_mm:.4f}",
            f"{q.AD_mm:.4f}",
            f"{p.RD_mm:.4f}",
            f"{q.RD_mm:.4f}",
        )
        for p, q in zip(b.distances, a.distances)
    ]
    gain = b.AP_max_mm / a.AP_max_mm if a.AP_max_mm > 0 else float("inf")
    decided, uncertainty = uncertainty_section(report)
    late = report.tracker_overdue
    overdue_head = (
        f' <span class="overdue" id="overdue">- tracker calibration overdue (due {escape(str(late))}):'
        " not passing</span>"
        if late
        else ""
    )
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>Accuracy certificate - {escape(report.robot)}</title>
<style>{CSS}</style></head><body>
<h1>Accuracy certificate{overdue_head}</h1>
<p class="note">Positioning accuracy and repeatability after calibration, measured per ISO 9283:1998
(clause 7.2: AP, RP and vAP; 7.3: AD and RD), commanded once with the nominal joints
and once with the model's compensated joints.</p>
{_table([], ident, "id")}
<p class="verdict" id="verdict">Worst-point accuracy AP: <b>{b.AP_max_mm:.4f} mm</b> with the
nominal joints, <b>{a.AP_max_mm:.4f} mm</b> compensated ({gain:.0f}x better); worst
repeatability RP {b.RP_max_mm:.4f} mm / {a.RP_max_mm:.4f} mm. {decided}</p>
<h2>Summary</h2>
{_table(["figure", "before (nominal)", "after (compensated)"], summary)}
<h2>Per test point (mm)</h2>
{_table(["point", "x", "y", "z", "AP before", "AP after", "RP before", "RP after", "vAP before", "vAP after"], points)}
{"<h2>Distance accuracy and repeatability (mm)</h2>" + _table(["pair", "AD before", "AD after", "RD before", "RD after"], distances) if distances else ""}
{uncertainty}
<h2>Plots</h2>
<figure><img alt="AP and RP per point" src="{figure_ap_rp(report)}"></figure>
<figure><img alt="attained less commanded positions" src="{figure_scatter(report)}"></figure>
<p class="note">AP: distance from the barycentre of the attained positions to the commanded
position; RP = l&#772; + 3 S<sub>l</sub> of the distances to that barycentre; vAP: widest gap
between the barycentres reached from each approach direction; AD: mean attained less commanded
distance between two points; RD = 3 S<sub>D</sub>.</p>
</body></html>
"""


def write_certificate(report: VerificationDoc, path) -> Path:
    """Write the certificate's HTML to path (whole, or not at all); the path."""
    path = Path(path)
    html = render(report)
    tmp = path.with_name(path.name + ".part")
    tmp.write_text(html, encoding="utf-8")
    tmp.replace(path)
    return path
