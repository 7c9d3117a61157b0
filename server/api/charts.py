"""Charts of a done calibration job: AP box plots and per-pose errors (PNG), the paper's Table 3."""

from __future__ import annotations

import io
import math
from dataclasses import dataclass

import numpy as np
from fastapi import APIRouter, Response
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from server import store
from server.formats.cell_json import parse_cell
from server.formats.model_json import read_model
from server.workflow import compare, model_predict, paper_methods, run_method
from solver import metrics
from solver.kinematics import predict

from .deps import DbDep, JobId, JobsDep

router = APIRouter(prefix="/charts", tags=["charts"])
PNG = {200: {"content": {"image/png": {}}}}


@dataclass
class _Errors:
    """AP error (mm) per pose and SMR, before (nominal) and after the job's model."""

    method: str
    targets: tuple[str, ...]
    before: np.ndarray  # (m, K), NaN where no reading
    after: np.ndarray


def _campaign(db, job):
    """The job's campaign as (cell, measurements), as the job read it."""
    info = store.get_campaign(db, campaign_id=job.campaign_id)
    cell = parse_cell(info.cell_json, f"<campaign {job.campaign_id} cell>")
    return cell, store.campaign_measurements(db, campaign_id=job.campaign_id, robot=cell.robot)


def _errors(db, jobs, job_id: int) -> _Errors:
    """Per-pose AP errors of a done job (NotFound / Conflict through jobs.model_path)."""
    path = jobs.model_path(job_id)
    job = jobs.get(job_id)
    cell, meas = _campaign(db, job)
    model = read_model(path)
    names = meas.target_names
    order = [list(model.targets).index(t) for t in names]
    after = model_predict(model, meas.q)[:, order]
    nominal = run_method(cell, meas, "nominal")
    before = predict(nominal.layout, nominal.x, meas.q)
    return _Errors(job.method, tuple(names), metrics.position_errors(before, meas.xyz),
                   metrics.position_errors(after, meas.xyz))


def _png(fig: Figure) -> Response:
    # A bare Figure on the Agg canvas, not pyplot: routes run on the threadpool and pyplot's
    # global state is not thread-safe.
    buf = io.BytesIO()
    FigureCanvasAgg(fig).print_png(buf)
    # Cheap to redraw, and a new database behind the same URL must never show a stale chart.
    return Response(buf.getvalue(), media_type="image/png", headers={"Cache-Control": "no-store"})


def _finite(a: np.ndarray) -> np.ndarray:
    return a[np.isfinite(a)]


@router.get("/jobs/{job_id}/boxplot.png", response_class=Response, responses=PNG)
def boxplot(job_id: JobId, db: DbDep, jobs: JobsDep) -> Response:
    """AP error per SMR before (nominal) and after calibration, as the paper's Figures 2-6."""
    e = _errors(db, jobs, job_id)
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


@router.get("/jobs/{job_id}/errors.png", response_class=Response, responses=PNG)
def errors(job_id: JobId, db: DbDep, jobs: JobsDep) -> Response:
    """AP error per pose (worst SMR of the pose) before and after calibration."""
    e = _errors(db, jobs, job_id)
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


def _num(v) -> float | None:
    """JSON has no NaN: missing values are null."""
    return None if v is None or not math.isfinite(v) else float(v)


@router.get("/jobs/{job_id}/table3")
def table3(job_id: JobId, db: DbDep, jobs: JobsDep) -> dict:
    """The paper's Table 3 for the job's campaign: every method on its data, side by side."""
    job = jobs.get(job_id)
    cell, meas = _campaign(db, job)
    if meas.n_poses == 0:
        raise store.StoreError(f"campaign {job.campaign_id} has no readings")
    rows = compare(cell, meas, paper_methods(meas.target_names))
    accs = [acc for _, acc in rows.values()]
    table = [(f"F_{n} / mm^2", [a["F"][n] for a in accs]) for n in meas.target_names]
    table += [("max F_i / mm^2", [max(a["F"].values()) for a in accs]),
              ("RMSE(phi) / mm", [a["rmse_phi"] for a in accs]),
              ("AP mean / mm", [a["ap"]["mean"] for a in accs]),
              ("AP std / mm", [a["ap"]["std"] for a in accs]),
              ("AP max / mm", [a["ap"]["max"] for a in accs])]
    if "ao_log" in accs[0]:
        table += [("AO' mean / deg", [a["ao_log"]["mean"] for a in accs]),
                  ("AO' max / deg", [a["ao_log"]["max"] for a in accs])]
    table.append(("time / ms", [cal.seconds * 1000 for cal, _ in rows.values()]))
    return {"job_id": job_id, "campaign_id": job.campaign_id, "method": job.method,
            "poses": meas.n_poses, "targets": list(meas.target_names), "columns": list(rows),
            "rows": [{"label": label, "values": [_num(v) for v in values]}
                     for label, values in table]}


__all__ = ["router"]
