"""Charts of a done calibration job, drawn in a worker process (server.service.processes): AP box plots
and per-pose errors (PNG bytes), the paper's Table 3, and a model's evaluation on a campaign.

Each takes the data the route read (a model path, the campaign's cell JSON and readings) and a
trailing `report` (unused: they report nothing on the way).
"""

from __future__ import annotations

import io
from dataclasses import dataclass

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from robocal.server.calibration.validation import json_number
from robocal.server.calibration.workflow import (
    compare,
    evaluate,
    model_predict,
    paper_methods,
    run_method,
)
from robocal.server.formats.cell_json import parse_cell
from robocal.server.formats.model_json import read_model
from robocal.solver import metrics
from robocal.solver.kinematics import predict
from robocal.solver.measurements import Measurements


@dataclass
class _Errors:
    """AP error (mm) per pose and SMR, before (nominal) and after the job's model."""

    method: str
    targets: tuple[str, ...]
    before: np.ndarray  # (m, K), NaN where no reading
    after: np.ndarray


def _errors(model_path, cell_json: str, meas: Measurements, method: str) -> _Errors:
    cell = parse_cell(cell_json, "<campaign cell>")
    model = read_model(model_path)
    names = meas.target_names
    order = [list(model.targets).index(t) for t in names]
    after = model_predict(model, meas.q)[:, order]
    nominal = run_method(cell, meas, "nominal")
    before = predict(nominal.layout, nominal.x, meas.q)
    return _Errors(
        method,
        tuple(names),
        metrics.position_errors(before, meas.xyz),
        metrics.position_errors(after, meas.xyz),
    )


def _png(fig: Figure) -> bytes:
    # A bare Figure on the Agg canvas, not pyplot, whose global state is not thread-safe.
    buf = io.BytesIO()
    FigureCanvasAgg(fig).print_png(buf)
    return buf.getvalue()


def _finite(a: np.ndarray) -> np.ndarray:
    return a[np.isfinite(a)]


def boxplot_png(
    job_id: int, model_path, cell_json: str, meas: Measurements, method: str, report=None
) -> bytes:
    """AP error per SMR before (nominal) and after calibration, as the paper's Figures 2-6."""
    e = _errors(model_path, cell_json, meas, method)
    fig = Figure(figsize=(8, 4.5), constrained_layout=True)
    ax = fig.add_subplot()
    data, labels, colors = [], [], []
    for k, name in enumerate(e.targets):
        for arr, when, color in ((e.before, "nominal", "#d08770"), (e.after, e.method, "#5e81ac")):
            data.append(_finite(arr[:, k]))
            labels.append(f"{name}\n{when}")
            colors.append(color)
    box = ax.boxplot(data, patch_artist=True, showmeans=True)
    for patch, color in zip(box["boxes"], colors):
        patch.set_facecolor(color)
        patch.set_alpha(0.6)
    ax.set_xticks(range(1, len(labels) + 1), labels, fontsize=8)
    ax.set_yscale("log")  # nominal errors are often 10-100x the calibrated ones
    ax.set_ylabel("AP error / mm")
    ax.set_title(f"Job {job_id}: AP error per SMR, nominal vs {e.method}")
    ax.grid(alpha=0.3, axis="y", which="both")
    return _png(fig)


def errors_png(
    job_id: int, model_path, cell_json: str, meas: Measurements, method: str, report=None
) -> bytes:
    """AP error per pose (worst SMR of the pose) before and after calibration."""
    e = _errors(model_path, cell_json, meas, method)
    fig = Figure(figsize=(8, 4.5), constrained_layout=True)
    ax = fig.add_subplot()
    poses = np.arange(1, len(e.before) + 1)
    with np.errstate(invalid="ignore"):  # all-NaN poses stay NaN: a gap in the line
        worst_before = np.fmax.reduce(e.before, axis=1)
        worst_after = np.fmax.reduce(e.after, axis=1)
    ax.plot(poses, worst_before, "o-", ms=3, color="#d08770", label="nominal")
    ax.plot(poses, worst_after, "o-", ms=3, color="#5e81ac", label=e.method)
    ax.set_yscale("log")
    ax.set_xlabel("pose")
    ax.set_ylabel("max AP error over SMRs / mm")
    ax.set_title(f"Job {job_id}: error per pose before and after calibration")
    ax.legend(loc="best")
    ax.grid(alpha=0.3, which="both")
    return _png(fig)


def table3(cell_json: str, meas: Measurements, report=None) -> dict:
    """The paper's Table 3 for a campaign: every method on its data, side by side (columns and
    rows; the route adds the job's ids)."""
    cell = parse_cell(cell_json, "<campaign cell>")
    rows = compare(cell, meas, paper_methods(meas.target_names))
    accs = [acc for _, acc in rows.values()]
    table = [(f"F_{n} / mm^2", [a.F[n] for a in accs]) for n in meas.target_names]
    table += [
        ("max F_i / mm^2", [max(a.F.values()) for a in accs]),
        ("RMSE(phi) / mm", [a.rmse_phi for a in accs]),
        ("AP mean / mm", [a.ap.mean for a in accs]),
        ("AP std / mm", [a.ap.std for a in accs]),
        ("AP max / mm", [a.ap.max for a in accs]),
    ]
    if accs[0].ao_log is not None:  # every method on the same data has one when the first has
        nan = float("nan")
        table += [
            ("AO' mean / deg", [a.ao_log.mean if a.ao_log else nan for a in accs]),
            ("AO' max / deg", [a.ao_log.max if a.ao_log else nan for a in accs]),
        ]
    table.append(("time / ms", [cal.seconds * 1000 for cal, _ in rows.values()]))
    return {
        "poses": meas.n_poses,
        "targets": list(meas.target_names),
        "columns": list(rows),
        "rows": [
            {"label": label, "values": [json_number(v) for v in values]} for label, values in table
        ],
    }


def evaluation(model_path, meas: Measurements, report=None) -> metrics.Evaluation:
    """Accuracy of a model file on a campaign's readings, next to the nominal model."""
    return evaluate(read_model(model_path), meas)


__all__ = ["boxplot_png", "errors_png", "evaluation", "table3"]
