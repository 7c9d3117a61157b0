"""A calibration as a Rerun recording (.rrd): the arm at each pose, SMRs, errors and the solver."""

from __future__ import annotations

import os
import re
import tempfile
from pathlib import Path

import numpy as np

# Never phone home: the recording goes to a file and the workstation may be offline.
os.environ.setdefault("RERUN_ANALYTICS", "0")

import rerun as rr  # noqa: E402
from robocal.solver.calibrate import Calibration  # noqa: E402
from robocal.solver.kinematics import flange_frames, joint_frames, predict  # noqa: E402
from robocal.solver.measurements import Measurements  # noqa: E402

from .formats.cell_json import Cell  # noqa: E402

MEASURED = (220, 220, 220)
BEFORE = (255, 140, 0)
AFTER = (40, 140, 255)
ARM = {"before": (255, 190, 110), "after": (120, 180, 255)}


def _chain(cal: Calibration, q) -> tuple[np.ndarray, np.ndarray]:
    """Per pose, base origin, joint frame origins and flange (m, n+2, 3); flange R (m, 3, 3)."""
    q = np.atleast_2d(q)
    base = np.broadcast_to(cal.layout.base(cal.x)[:3, 3], (len(q), 3))
    origins = [o for _, o in joint_frames(cal.layout, cal.x, q)]
    R, o = flange_frames(cal.layout, cal.x, q)
    return np.stack([base, *origins, o], axis=1), R


def _rms(err: np.ndarray) -> np.ndarray:
    """3-D RMS error per pose over its measured readings (NaN where none)."""
    sq = np.sum(err * err, axis=-1)
    ok = np.isfinite(sq)
    n = ok.sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.sqrt(np.where(ok, sq, 0.0).sum(axis=1) / n)


def _slug(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9_]+", "_", text).strip("_") or "effect"


def _log_diagnosis(rec: rr.RecordingStream, figures: list[dict]) -> None:
    """Each figure as 2-D scatters (before, expected, after) and as the PNG server/plots.py draws."""
    from .plots import effect_figure  # matplotlib only when there is something to draw

    with tempfile.TemporaryDirectory() as tmp:
        for i, fig in enumerate(figures, start=1):
            root = f"diagnosis/{i}_{_slug(fig.get('name', fig['label']))}"
            x = np.asarray(fig["x"], dtype=float)
            for key, color in (("before", BEFORE), ("expected", (220, 40, 40)), ("after", AFTER)):
                y = np.asarray(fig[key], dtype=float)
                # scatter apart from the PNG: data units and pixels should not share one 2-D space
                ok = np.isfinite(x) & np.isfinite(y)
                scatter = rr.Points2D(
                    np.stack([x[ok], y[ok]], axis=1), colors=color, radii=rr.Radius.ui_points(3.0)
                )
                rec.log(f"{root}/scatter/{key}", scatter, static=True)
            rec.log(
                f"{root}/axes",
                rr.TextDocument(f"{fig['label']}\n\nx: {fig['x_label']}\ny: {fig['y_label']}"),
                static=True,
            )
            png = effect_figure(fig, Path(tmp) / f"{i}.png")
            rec.log(
                f"{root}/figure",
                rr.EncodedImage(contents=png.read_bytes(), media_type="image/png"),
                static=True,
            )


def record_calibration(
    path,
    *,
    cell: Cell,
    meas: Measurements,
    calibration: Calibration,
    nominal: Calibration | None = None,
    diagnosis=None,
    magnify: float = 100.0,
    viewer_url: str | None = None,
) -> Path:
    """Write a .rrd of a calibration: per pose (timeline "pose") arm, SMRs, errors; the solver's history.

    With viewer_url (a running viewer's gRPC address, e.g. rerun+http://127.0.0.1:9876/proxy)
    the same data is also streamed to it live.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    if nominal is None:
        from .workflow import run_method  # workflow imports heavy pieces; keep this module light

        nominal = run_method(cell, meas, "nominal")
    q, xyz = meas.q, meas.xyz
    models = {"before": nominal, "after": calibration}
    pred = {k: predict(c.layout, c.x, q) for k, c in models.items()}
    chain = {k: _chain(c, q) for k, c in models.items()}
    err = {k: p - xyz for k, p in pred.items()}  # NaN where the reading is missing
    rms = {k: _rms(e) for k, e in err.items()}
    names = list(meas.target_names)

    # An explicit stream, not the global one: several recordings may be written in one process,
    # and nothing is sent anywhere but the file (and the viewer, when one is configured).
    rec = rr.RecordingStream("robocal", send_properties=False)
    if viewer_url:
        rec.set_sinks(rr.FileSink(str(path)), rr.GrpcSink(viewer_url))
    else:
        rec.save(path)
    summary = (
        f"# Calibration\n\nmethod: {calibration.method}\n\nposes: {meas.n_poses}, "
        f"readings: {meas.n_readings}, targets: {', '.join(names)}\n\n"
        f"RMS error before: {np.sqrt(np.nanmean(rms['before'] ** 2)):.4f} mm, "
        f"after: {np.sqrt(np.nanmean(rms['after'] ** 2)):.4f} mm\n\n"
        f"error arrows magnified x{magnify:g}"
    )
    rec.log("summary", rr.TextDocument(summary, media_type=rr.MediaType.MARKDOWN), static=True)
    for k, color in (("before", BEFORE), ("after", AFTER)):
        rec.log(f"errors/rms/{k}", rr.SeriesLines(colors=color, names=f"RMS {k} / mm"), static=True)

    for i in range(meas.n_poses):
        rec.set_time("pose", sequence=i)
        ok = np.all(np.isfinite(xyz[i]), axis=-1)
        labels = [n for n, good in zip(names, ok) if good]
        rec.log(
            "world/smr/measured",
            rr.Points3D(xyz[i][ok], labels=labels, colors=MEASURED, radii=rr.Radius.ui_points(5.0)),
        )
        for k, color in (("before", BEFORE), ("after", AFTER)):
            pts, R = chain[k]
            # the chain to the flange, then the flange to each SMR it carries (the tool)
            strips = [pts[i]] + [np.stack([pts[i, -1], p]) for p in pred[k][i]]
            rec.log(
                f"world/arm/{k}",
                rr.LineStrips3D(strips, colors=ARM[k], radii=rr.Radius.ui_points(2.0)),
            )
            rec.log(
                f"world/arm/{k}/flange",
                rr.Transform3D(translation=pts[i, -1], mat3x3=R[i]),
                rr.TransformAxes3D(axis_length=100.0),
            )
            rec.log(
                f"world/smr/{k}",
                rr.Points3D(pred[k][i], labels=names, colors=color, radii=rr.Radius.ui_points(4.0)),
            )
            rec.log(
                f"world/error_vectors/{k}",
                rr.Arrows3D(
                    origins=xyz[i][ok],
                    vectors=magnify * err[k][i][ok],
                    colors=color,
                    radii=rr.Radius.ui_points(1.5),
                ),
            )
            if np.isfinite(rms[k][i]):
                rec.log(f"errors/rms/{k}", rr.Scalars(rms[k][i]))

    history = calibration.get("history")
    if history:
        rec.log("solver/max_F", rr.SeriesLines(colors=AFTER, names="max F_i / mm^2"), static=True)
        rec.disable_timeline("pose")
        for it, value in enumerate(history):
            rec.set_time("iteration", sequence=it)
            rec.log("solver/max_F", rr.Scalars(float(value)))
    if diagnosis is not None and diagnosis.figures:
        _log_diagnosis(rec, diagnosis.figures)
    rec.flush()
    rec.disconnect()  # closes the file sink so the footer is written before we return
    return path


__all__ = ["record_calibration"]
