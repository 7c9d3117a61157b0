"""A calibration as a Rerun recording (.rrd): the cell with every pose, each pose, the solver."""

from __future__ import annotations

import os
import re
import tempfile
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

# Never phone home: the recording goes to a file and the workstation may be offline.
os.environ.setdefault("RERUN_ANALYTICS", "0")

import rerun as rr  # noqa: E402

from robocal.server.formats.cell_json import Cell  # noqa: E402
from robocal.server.formats.model_json import ModelFile  # noqa: E402
from robocal.server.recordings.blueprint import calibration_blueprint, cell_eye  # noqa: E402
from robocal.server.recordings.cell import (  # noqa: E402
    MEASURED,
    Drawn,
    PoseSet,
    color_scale,
    error_colors,
    log_frames,
    log_poses,
    log_tracker_and_base,
    representative,
)
from robocal.solver.calibrate import Calibration  # noqa: E402
from robocal.solver.kinematics import flange_frames, joint_frames  # noqa: E402
from robocal.solver.measurements import Measurements  # noqa: E402

if TYPE_CHECKING:
    from robocal.server.calibration.workflow import Diagnosed
    from robocal.solver.diagnosis_report import EffectFigure

BEFORE = (255, 140, 0)
AFTER = (40, 140, 255)
GEOMETRIC = (150, 90, 220)
SERIES = {"before": BEFORE, "after": AFTER, "geometric": GEOMETRIC}
ARM = {"before": (255, 190, 110), "after": (120, 180, 255), "geometric": (170, 120, 230)}


def extended_model(model: ModelFile) -> Drawn:
    """A model file drawn with its extensions (a diagnosis's final model): its geometric arm,
    and its predictions as `evaluate` makes them."""
    from robocal.server.calibration.workflow import model_predict

    lay, x = model.layout()

    def predicted(meas: Measurements) -> np.ndarray:
        return model_predict(model, meas.q, _per_pose(meas.time_s), _per_pose(meas.temp_c))

    return Drawn(lay, x, predicted)


def _per_pose(a):
    """A per-reading column's value per pose (its first measured reading), None for none."""
    if a is None:
        return None
    return a[np.arange(len(a)), np.argmax(np.isfinite(a), axis=1)]


def _chain(cal: Calibration | Drawn, q) -> tuple[np.ndarray, np.ndarray]:
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


def _log_diagnosis(rec: rr.RecordingStream, figures: list[EffectFigure]) -> list[tuple[str, str]]:
    """Each figure as 2-D scatters (before, expected, after) and as the PNG server/figures/diagnosis.py draws.

    Returns (entity, title) of each figure's image, for the blueprint.
    """
    from robocal.server.figures.diagnosis import (
        effect_figure,  # matplotlib only when there is something to draw
    )

    shown = []
    with tempfile.TemporaryDirectory() as tmp:
        for i, fig in enumerate(figures, start=1):
            root = f"diagnosis/{i}_{_slug(fig.name)}"
            x = np.asarray(fig.x, dtype=float)
            for key, color in (("before", BEFORE), ("expected", (220, 40, 40)), ("after", AFTER)):
                y = np.asarray(getattr(fig, key), dtype=float)
                # scatter apart from the PNG: data units and pixels should not share one 2-D space
                ok = np.isfinite(x) & np.isfinite(y)
                scatter = rr.Points2D(
                    np.stack([x[ok], y[ok]], axis=1), colors=color, radii=rr.Radius.ui_points(3.0)
                )
                rec.log(f"{root}/scatter/{key}", scatter, static=True)
            rec.log(
                f"{root}/axes",
                rr.TextDocument(f"{fig.label}\n\nx: {fig.x_label}\ny: {fig.y_label}"),
                static=True,
            )
            png = effect_figure(fig, Path(tmp) / f"{i}.png")
            rec.log(
                f"{root}/figure",
                rr.EncodedImage(contents=png.read_bytes(), media_type="image/png"),
                static=True,
            )
            shown.append((f"{root}/figure", fig.label))
    return shown


def _log_per_pose(
    rec: rr.RecordingStream, sets: list[PoseSet], models: dict, magnify: float, top: float
) -> None:
    """Timeline "pose" (calibration poses, then held-out ones): the arm, its SMRs and errors.

    Sent as columns, one call per entity: a thousand poses cost milliseconds, not a log call each.
    """
    q = np.concatenate([s.meas.q for s in sets])
    xyz = np.concatenate([s.meas.xyz for s in sets])
    ok = np.all(np.isfinite(xyz), axis=-1)
    counts = ok.sum(axis=1)
    pose = [rr.TimeColumn("pose", sequence=np.arange(len(q)))]
    rec.send_columns(
        "world/pose/smr/measured",
        pose,
        rr.Points3D.columns(positions=xyz[ok]).partition(counts),
    )
    rec.log("world/pose/smr/measured", rr.Points3D.from_fields(colors=MEASURED), static=True)
    for k, model in models.items():
        pts, R = _chain(model, q)
        pred = np.concatenate([s.pred[k] for s in sets])
        err = np.concatenate([s.err[k] for s in sets])
        # the chain to the flange, then the flange to each SMR it carries (the tool)
        strips = [
            strip
            for i in range(len(q))
            for strip in [pts[i], *(np.stack([pts[i, -1], p]) for p in pred[i])]
        ]
        per = 1 + pred.shape[1]
        rec.send_columns(
            f"world/pose/arm/{k}",
            pose,
            rr.LineStrips3D.columns(strips=strips).partition(np.full(len(q), per)),
        )
        rec.log(
            f"world/pose/arm/{k}",
            rr.LineStrips3D.from_fields(colors=ARM[k], radii=rr.Radius.ui_points(2.0)),
            static=True,
        )
        rec.send_columns(
            f"world/pose/arm/{k}/flange",
            pose,
            rr.Transform3D.columns(translation=pts[:, -1], mat3x3=R),
        )
        rec.log(f"world/pose/arm/{k}/flange", rr.TransformAxes3D(axis_length=100.0), static=True)
        e = err[ok]
        rec.send_columns(
            f"world/pose/error/{k}",
            pose,
            rr.Arrows3D.columns(
                origins=pred[ok],
                vectors=magnify * e,
                colors=error_colors(np.linalg.norm(e, axis=-1), top),
            ).partition(counts),
        )


def _log_error_per_pose(rec: rr.RecordingStream, sets: list[PoseSet]) -> None:
    """Each pose's RMS error before and after (and the geometric model's beside a diagnosis's
    final one): a series on timeline "pose", and static bars."""
    start = 0
    for s in sets:
        for k, color in ((k, SERIES[k]) for k in SERIES if k in s.err):
            rms = _rms(s.err[k])
            good = np.isfinite(rms)
            path = f"errors/rms/{s.name}/{k}"
            rec.log(path, rr.SeriesLines(colors=color, names=f"{s.name} {k} / mm"), static=True)
            if good.any():
                rec.send_columns(
                    path,
                    [rr.TimeColumn("pose", sequence=start + np.flatnonzero(good))],
                    rr.Scalars.columns(scalars=rms[good]),
                )
            # the same as bars, static: seen whichever timeline the viewer is on
            width = 0.8 / len(s.err)
            offset = (list(s.err).index(k) - (len(s.err) - 1) / 2) * width
            rec.log(
                f"errors/per_pose/{s.name}/{k}",
                rr.BarChart(
                    np.nan_to_num(rms),
                    abscissa=start + np.arange(len(rms)) + offset,
                    widths=np.full(len(rms), width),
                    color=color if s.name == "calibration" else tuple(c // 2 for c in color),
                ),
                static=True,
            )
        start += s.meas.n_poses


def _summary(
    calibration, sets: list[PoseSet], magnify: float, top: float, frames_at: str, final=None
) -> str:
    """Markdown: the RMS errors first (what fits the view), then how to read the cell."""
    keys = list(sets[0].err)
    rows = [
        "| poses | readings | " + " | ".join(f"RMS {k}" for k in keys) + " |",
        "|---|---|" + "---|" * len(keys),
    ]
    for s in sets:
        rms = {k: float(np.sqrt(np.nanmean(np.sum(e * e, axis=-1)))) for k, e in s.err.items()}
        rows.append(
            f"| {s.name}: {s.meas.n_poses} | {s.meas.n_readings} | "
            + " | ".join(f"{rms[k]:.4f} mm" for k in keys)
            + " |"
        )
    said = (
        f"before: the nominal model, after: the diagnosis's final model **{final}**, geometric: "
        f"the {calibration.method} calibration without extensions"
        if final
        else "before: the nominal model, after: the identified one"
    )
    lines = [
        f"**{calibration.method}** on targets {', '.join(sets[0].meas.target_names)}; {said}",
        "\n".join(rows),
    ]
    if len(sets) == 1:
        lines.append("no held-out poses: every pose of the campaign was fitted")
    lines += [
        f"error arrows: measured less predicted, from the predicted SMR, magnified x{magnify:g} "
        f"(1 mm error = {magnify:g} mm arrow); colour by size, green 0 mm, yellow "
        f"{top / 2:g} mm, red {top:g} mm and above",
        f"frames: nominal and identified joint frames at pose {frames_at} "
        "(nearest the mean joint vector)",
        "timelines: pose (one pose at a time), iteration (the solver)",
    ]
    return "\n\n".join(lines)


def record_calibration(
    path,
    *,
    cell: Cell,
    meas: Measurements,
    calibration: Calibration,
    nominal: Calibration | None = None,
    held_out: Measurements | None = None,
    diagnosis=None,
    extended: ModelFile | None = None,
    magnify: float = 100.0,
    viewer_url: str | None = None,
) -> Path:
    """Write a .rrd of a calibration: the cell with every pose, each pose, the solver's history.

    meas: the poses the calibration was fitted on; held_out: poses it did not see, if any.
    nominal: the nominal model registered on meas (fitted here when not given). extended: the
    diagnosis's final model (its model file), then "after" and the calibration "geometric"
    beside it. With viewer_url
    (a running viewer's gRPC address, e.g. rerun+http://127.0.0.1:9876/proxy) the same data is
    also streamed to it live.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    if nominal is None:
        from robocal.server.calibration.workflow import (
            run_method,  # workflow imports heavy pieces; keep this module light
        )

        nominal = run_method(cell, meas, "nominal")
    models = {"before": Drawn.of(nominal), "after": Drawn.of(calibration)}
    if extended is not None:
        models = {**models, "after": extended_model(extended), "geometric": models["after"]}
    sets = [PoseSet.of("calibration", meas, models)]
    if held_out is not None and held_out.n_poses:
        sets.append(PoseSet.of("held_out", held_out, models))
    top = color_scale(sets)

    # An explicit stream, not the global one: several recordings may be written in one process,
    # and nothing is sent anywhere but the file (and the viewer, when one is configured).
    rec = rr.RecordingStream("robocal", send_properties=False)
    if viewer_url:
        rec.set_sinks(rr.FileSink(str(path)), rr.GrpcSink(viewer_url))
    else:
        rec.save(path)
    readings = np.concatenate([s.meas.xyz[s.meas.mask] for s in sets])
    log_tracker_and_base(rec, models, readings)
    for s in sets:
        log_poses(rec, s, magnify, top)
    at = representative(meas.q)
    arm = log_frames(rec, models, meas, at)
    _log_per_pose(rec, sets, models, magnify, top)
    _log_error_per_pose(rec, sets)
    final = None if extended is None or extended.diagnosis is None else extended.diagnosis.final
    summary = _summary(calibration, sets, magnify, top, meas.pose_ids[at], final and final.model)
    rec.log("summary", rr.TextDocument(summary, media_type=rr.MediaType.MARKDOWN), static=True)

    history = calibration.history
    if history:
        rec.log("solver/max_F", rr.SeriesLines(colors=AFTER, names="max F_i / mm^2"), static=True)
        rec.send_columns(
            "solver/max_F",
            [rr.TimeColumn("iteration", sequence=np.arange(len(history)))],
            rr.Scalars.columns(scalars=np.asarray(history, dtype=float)),
        )
    figures = []
    if diagnosis is not None and diagnosis.figures:
        figures = _log_diagnosis(rec, diagnosis.figures)
    eye = cell_eye(np.vstack([readings, np.zeros((1, 3))]), models["after"].base)
    blueprint = calibration_blueprint(
        eye=eye,
        arm_eye=cell_eye(arm, models["after"].base),
        has_solver=bool(history),
        figures=figures,
    )
    rec.send_blueprint(blueprint)
    rec.flush()
    rec.disconnect()  # closes the file sink so the footer is written before we return
    return path


__all__ = ["record_calibration"]


def record_diagnosis(
    path,
    *,
    cell: Cell,
    meas: Measurements,
    diagnosed: Diagnosed,
    model: ModelFile,
    viewer_url: str | None = None,
) -> Path:
    """Write a .rrd of a diagnosis: "after" its final model, the geometry (ls-sum on the same
    readings) beside it, the effects' figures."""
    geometric = diagnosed.geometric
    if geometric is None:  # a diagnosis without standard errors judged no geometry
        from robocal.server.calibration.workflow import run_method

        geometric = run_method(cell, meas, "ls-sum")
    return record_calibration(
        path,
        cell=cell,
        meas=meas,
        calibration=geometric,
        diagnosis=diagnosed,
        extended=model,
        viewer_url=viewer_url,
    )
