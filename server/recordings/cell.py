"""The calibrated cell in a rerun recording: tracker, base frames, floor, every pose's error."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import rerun as rr

from robocal.solver.calibrate import Calibration
from robocal.solver.kinematics import Layout, flange_frames, joint_frames, predict
from robocal.solver.measurements import Measurements

# green (no error) -> yellow -> red (at the top of the scale and above)
STOPS = np.array([[40, 170, 60], [240, 200, 40], [220, 40, 40]], dtype=float)
MEASURED = (200, 200, 200)
FLOOR = (150, 150, 150)
FRAMES = {
    "nominal": (255, 190, 110),
    "identified": (120, 180, 255),
    "geometric": (170, 120, 230),
}
# error entity -> the model it judges; "geometric" only beside a diagnosis's final model
MODELS = {"before": "nominal", "after": "identified", "geometric": "geometric"}
GRID_MM = 500.0


@dataclass(frozen=True)
class Drawn:
    """A model as the recording draws it: the kinematics of its arm and what it predicts."""

    layout: Layout
    x: np.ndarray
    predict: Callable[[Measurements], np.ndarray]  # SMR centres (m, K, 3), mm

    @property
    def base(self) -> np.ndarray:
        return self.layout.base(self.x)

    @classmethod
    def of(cls, cal: Calibration) -> Drawn:
        """A calibration's geometric model."""
        return cls(cal.layout, cal.x, lambda meas: predict(cal.layout, cal.x, meas.q))


def drawn(model: Drawn | Calibration) -> Drawn:
    return model if isinstance(model, Drawn) else Drawn.of(model)


def models_of(models: dict) -> dict:
    """The entity keys (before, after, geometric) present, in MODELS' order."""
    return {k: v for k, v in MODELS.items() if k in models}


@dataclass
class PoseSet:
    """Poses of one kind (calibration or held-out) with each model's error on them."""

    name: str
    meas: Measurements
    err: dict  # "before"/"after"/"geometric" -> (m, K, 3) measured less predicted, mm (NaN: none)
    pred: dict  # the same keys -> (m, K, 3) predicted SMR centres, mm

    @classmethod
    def of(cls, name: str, meas: Measurements, models: dict) -> PoseSet:
        """models: per key a Drawn model, or a calibration (drawn as its geometric model)."""
        pred = {k: drawn(c).predict(meas) for k, c in models.items()}
        return cls(name, meas, {k: meas.xyz - p for k, p in pred.items()}, pred)


def error_colors(mm: np.ndarray, top: float) -> np.ndarray:
    """RGB (n, 3) uint8 per error size: green at 0, yellow at top/2, red at top and above."""
    t = np.clip(np.nan_to_num(np.asarray(mm, float) / top, nan=1.0), 0.0, 1.0) * 2.0
    lo = np.minimum(t.astype(int), 1)
    f = (t - lo)[:, None]
    return np.round(STOPS[lo] * (1 - f) + STOPS[lo + 1] * f).astype(np.uint8)


def color_scale(sets: list[PoseSet]) -> float:
    """The top of the colour scale (mm): the nominal model's 95th percentile, on a 1-2-5 step."""
    e = np.concatenate([np.linalg.norm(s.err["before"], axis=-1).ravel() for s in sets])
    p95 = float(np.nanpercentile(e, 95)) if np.isfinite(e).any() else 1.0
    steps = [m * 10.0**k for k in range(-2, 5) for m in (1, 2, 5)]
    return next((s for s in steps if s >= p95), steps[-1])


def _frame(rec: rr.RecordingStream, path: str, T: np.ndarray, axes_mm: float | None) -> None:
    """A 4x4 transform (tracker frame) on an entity, with its axes drawn axes_mm long."""
    parts: list[rr.Transform3D | rr.TransformAxes3D] = [
        rr.Transform3D(translation=T[:3, 3], mat3x3=T[:3, :3])
    ]
    if axes_mm:
        parts.append(rr.TransformAxes3D(axis_length=axes_mm))
    rec.log(path, *parts, static=True)


def log_tracker_and_base(
    rec: rr.RecordingStream, models: dict[str, Drawn], points: np.ndarray
) -> None:
    """The tracker at the origin (readings are in its frame), both base frames, and the floor.

    The floor is the identified base's xy plane (the arm stands on it), a grid wide enough for
    every reading and the tracker's foot; `points` (n, 3) are the readings in the tracker frame.
    """
    rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
    _frame(rec, "world/tracker", np.eye(4), 300.0)
    rec.log(
        "world/tracker/head",
        rr.Ellipsoids3D(
            radii=[90.0],
            centers=[[0.0, 0.0, 0.0]],
            colors=[(230, 230, 230)],
            labels=["laser tracker (readings are in its frame)"],
            fill_mode="solid",
        ),
        static=True,
    )
    base = models["after"].base
    for k, model in models_of(models).items():
        T = models[k].base
        _frame(rec, f"world/base/{model}", T, 400.0)
        rec.log(
            f"world/base/{model}/origin",
            rr.Points3D([[0.0, 0.0, 0.0]], colors=FRAMES[model], labels=[f"base ({model})"]),
            static=True,
        )
    # the tracker's foot and the readings, in the base frame, size the floor
    inv = np.linalg.inv(base)
    local = np.vstack([points, np.zeros((1, 3))]) @ inv[:3, :3].T + inv[:3, 3]
    foot_local = np.array([local[-1, 0], local[-1, 1], 0.0])
    lo = np.floor((local[:, :2].min(axis=0) - GRID_MM) / GRID_MM) * GRID_MM
    hi = np.ceil((local[:, :2].max(axis=0) + GRID_MM) / GRID_MM) * GRID_MM
    lo, hi = np.minimum(lo, -GRID_MM), np.maximum(hi, GRID_MM)  # always around the base
    xs = np.arange(lo[0], hi[0] + 1, GRID_MM)
    ys = np.arange(lo[1], hi[1] + 1, GRID_MM)
    lines = [[[x, lo[1], 0.0], [x, hi[1], 0.0]] for x in xs]
    lines += [[[lo[0], y, 0.0], [hi[0], y, 0.0]] for y in ys]
    _frame(rec, "world/floor", base, None)
    rec.log(
        "world/floor/grid",
        rr.LineStrips3D(lines, colors=FLOOR, radii=rr.Radius.ui_points(1.0)),
        static=True,
    )
    rec.log(
        "world/floor/plane",
        rr.Boxes3D(
            centers=[[(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, 0.0]],
            half_sizes=[[(hi[0] - lo[0]) / 2, (hi[1] - lo[1]) / 2, 0.0]],
            colors=[(120, 120, 120, 50)],
            fill_mode="solid",
            labels=[f"floor: the identified base's xy plane, grid {GRID_MM:g} mm"],
            show_labels=False,
        ),
        static=True,
    )
    foot = base[:3, :3] @ foot_local + base[:3, 3]
    rec.log(
        "world/tracker/stand",
        rr.LineStrips3D([[[0.0, 0.0, 0.0], foot]], colors=FLOOR, radii=rr.Radius.ui_points(3.0)),
        static=True,
    )


def log_poses(rec: rr.RecordingStream, s: PoseSet, magnify: float, top: float) -> None:
    """Every pose of the set at once: readings, and each model's error as coloured arrows."""
    xyz = s.meas.xyz
    ok = np.all(np.isfinite(xyz), axis=-1)
    root = f"world/poses/{s.name}"
    rec.log(
        f"{root}/measured",
        rr.Points3D(xyz[ok], colors=MEASURED, radii=rr.Radius.ui_points(3.0)),
        static=True,
    )
    for k, model in models_of(s.err).items():
        e = s.err[k][ok]
        rec.log(
            f"{root}/error/{k}",
            rr.Arrows3D(
                origins=s.pred[k][ok],
                vectors=magnify * e,
                colors=error_colors(np.linalg.norm(e, axis=-1), top),
                radii=rr.Radius.ui_points(1.5),
                labels=[
                    f"{s.name} poses, {k} ({model} model): measured less predicted, x{magnify:g} "
                    f"(1 mm = {magnify:g} mm arrow); colour green 0 -> red {top:g} mm"
                ],
                show_labels=False,
            ),
            static=True,
        )


def representative(q: np.ndarray) -> int:
    """The pose nearest the campaign's mean joint vector."""
    return int(np.argmin(np.linalg.norm(q - q.mean(axis=0), axis=1)))


def log_frames(
    rec: rr.RecordingStream, models: dict[str, Drawn], meas: Measurements, i: int
) -> np.ndarray:
    """Joint frames, links and the flange of each model at pose i, nominal beside identified
    (and the geometric one beside a diagnosis's final model).

    Returns the identified chain's points (base, joints, flange, SMRs), to aim a view at.
    """
    q = meas.q[i : i + 1]
    out = np.zeros((0, 3))
    for k, model in models_of(models).items():
        c = models[k]
        root = f"world/frames/{model}"
        frames = joint_frames(c.layout, c.x, q)
        for j, (R, o) in enumerate(frames, start=1):
            T = np.eye(4)
            T[:3, :3], T[:3, 3] = R[0], o[0]
            _frame(rec, f"{root}/joint_{j}", T, 150.0)
        R, o = flange_frames(c.layout, c.x, q)
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = R[0], o[0]
        _frame(rec, f"{root}/flange", T, 100.0)
        chain = np.vstack([c.base[:3, 3], *(o_[0] for _, o_ in frames), o[0]])
        smr = predict(c.layout, c.x, q)[0]
        rec.log(
            f"{root}/links",
            rr.LineStrips3D(
                [chain] + [np.stack([o[0], p]) for p in smr],
                colors=FRAMES[model],
                radii=rr.Radius.ui_points(2.0),
                labels=[f"{model} frames at pose {meas.pose_ids[i]}"],
                show_labels=False,
            ),
            static=True,
        )
        if k == "after":
            out = np.vstack([chain, smr])
    return out


__all__ = [
    "Drawn",
    "PoseSet",
    "drawn",
    "models_of",
    "color_scale",
    "error_colors",
    "log_frames",
    "log_poses",
    "log_tracker_and_base",
    "representative",
]
