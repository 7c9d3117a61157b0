"""`robocal compensate`: a model file and a targets file in, joint commands out."""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np
from robocal.solver.compensate import Compensation, Model, compensate
from robocal.solver.kinematics import Layout, rot

from .formats.errors import InputError
from .formats.model_json import ModelFile, read_model
from .formats.targets_csv import Targets, read_targets

TCP_NAME = "TCP"  # the virtual SMR's name in targets.csv when a tool centre point is given
# an oriented tool is three virtual SMRs: its point and points this far along its x and z axes
LEVER_MM = 100.0
TOOL_POINTS = (TCP_NAME, "TCP_X", "TCP_Z")
MAX_ERROR_MM = 0.1  # a pose the model cannot bring closer than this is refused as unreachable


def parse_tcp(text: str) -> list[float]:
    """x,y,z[,rx,ry,rz] (mm, degrees) of a tool centre point in the flange frame; ValueError."""
    try:
        v = [float(p) for p in text.split(",")]
    except ValueError:
        v = []
    if len(v) not in (3, 6) or not all(np.isfinite(v)) or max(abs(c) for c in v) > 10_000:
        raise ValueError(
            f"{text!r} is not x,y,z[,rx,ry,rz]: the tool centre point in the flange frame, mm, "
            "and its orientation, degrees"
        )
    return v


def rotation(rx, ry, rz) -> np.ndarray:
    """Rz(rz) Ry(ry) Rx(rx), angles in degrees (KUKA's A, B, C order)."""
    return (rot(2, np.deg2rad(rz)) @ rot(1, np.deg2rad(ry)) @ rot(0, np.deg2rad(rx)))[:3, :3]


def tool_points(point, R) -> np.ndarray:
    """A tool frame (point (3,), rotation R (3, 3)) as its three virtual SMRs (3, 3)."""
    point = np.asarray(point, dtype=float)
    return np.array([point, point + LEVER_MM * R[:, 0], point + LEVER_MM * R[:, 2]])


def solver_model(model: ModelFile, tcp=None) -> Model:
    """The model file as the solver takes it; with tcp (x, y, z[, rx, ry, rz]) mm and degrees in
    the flange frame, the tool's three virtual SMRs (TOOL_POINTS) in place of the SMRs."""
    if tcp is None:
        lay, x = model.layout()
    else:
        tcp = list(tcp) + [0.0] * (6 - len(tcp))
        lay = Layout(model.robot, model.base, TOOL_POINTS)
        x = lay.initial(tool_points(tcp[:3], rotation(*tcp[3:])))
    return Model(lay, x, list(model.extensions), model.nominal or model.robot)


def tool_targets(targets: Targets) -> Targets:
    """targets.csv's TCP rows as the tool's virtual SMRs: its point, and where a pose gives the
    tool's orientation (rx, ry, rz in the cell frame), the points along its x and z axes."""
    m = len(targets.pose_ids)
    p = targets.desired[:, 0]
    desired = np.repeat(p[:, None], 3, axis=1)
    mask = np.zeros((m, 3), dtype=bool)
    mask[:, 0] = targets.mask[:, 0]
    turn = targets.orientation if targets.orientation is not None else np.full((m, 3), np.nan)
    for k in np.flatnonzero(np.all(np.isfinite(turn), axis=1)):
        desired[k] = tool_points(p[k], rotation(*turn[k]))
        mask[k] = True
    wide = lambda a: None if a is None else np.repeat(a[:, :1], 3, axis=1)  # noqa: E731
    return replace(
        targets,
        names=TOOL_POINTS,
        desired=desired,
        mask=mask,
        time_s=wide(targets.time_s),
        temp_c=wide(targets.temp_c),
    )


def compensate_targets(
    model: ModelFile, targets: Targets, tcp=None, max_error_mm: float = MAX_ERROR_MM
) -> Compensation:
    """The joint commands for these targets; InputError naming the file, line and pose of the
    first one the model cannot reach within the limits."""
    for e in model.extensions:
        need = e.kind.needs(e)
        if need and getattr(targets, need) is None:
            raise InputError(
                targets.path,
                1,
                None,
                f"the model's {e.label()} needs a {need} column (the {need} the program runs at)",
            )
        if need and not np.all(np.isfinite(getattr(targets, need))):
            k = int(np.flatnonzero(~np.all(np.isfinite(getattr(targets, need)), axis=1))[0])
            raise InputError(
                targets.path,
                targets.lines[k],
                None,
                f"pose {targets.pose_ids[k]!r}: the model's {e.label()} needs its {need}",
            )
    if tcp is not None:
        targets = tool_targets(targets)
    res = compensate(
        solver_model(model, tcp),
        targets.desired,
        targets.mask,
        targets.q0,
        targets.time_s,
        targets.temp_c,
    )
    bad = np.flatnonzero(~(res.error_mm <= max_error_mm))
    if len(bad):
        k = int(bad[0])
        raise InputError(
            targets.path,
            targets.lines[k],
            None,
            f"pose {targets.pose_ids[k]!r} is unreachable within the joint limits: the model "
            f"comes no closer than {res.error_mm[k]:.3f} mm RMS (at most {max_error_mm:g} mm "
            f"allowed){_more(len(bad))}",
        )
    return res


def _more(count: int) -> str:
    return f"; {count - 1} more poses unreachable" if count > 1 else ""


def compensate_file(model_path, targets_path, tcp=None, max_error_mm: float = MAX_ERROR_MM):
    """(pose ids, joint commands (m, n) degrees, predicted_error_mm (m,)) for a model file and a
    targets.csv; tcp (x, y, z[, rx, ry, rz]) mm and degrees in the flange frame makes `TCP` the
    one target, with an optional orientation per pose (rx, ry, rz columns). InputError on bad
    input or an unreachable pose (nothing is written here either way)."""
    model = read_model(model_path)
    names = (TCP_NAME,) if tcp is not None else tuple(model.targets)
    targets = read_targets(targets_path, model.robot, names, orientation=tcp is not None)
    res = compensate_targets(model, targets, tcp, max_error_mm)
    return targets.pose_ids, np.rad2deg(res.q), res.error_mm


def run(model_path, targets_path, out_path, tcp=None, max_error_mm: float = MAX_ERROR_MM):
    """Compensate and write joints.csv; returns a summary dict for the command's line."""
    from .formats.joints_csv import write_joints

    t0 = time.perf_counter()
    ids, q_deg, err = compensate_file(model_path, targets_path, tcp, max_error_mm)
    write_joints(out_path, ids, q_deg, err)
    return {
        "poses": len(ids),
        "worst_mm": float(err.max()),
        "rms_mm": float(np.sqrt(np.mean(err**2))),
        "seconds": time.perf_counter() - t0,
    }
