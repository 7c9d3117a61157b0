"""`robocal compensate`: a model file and a targets file in, joint commands out."""

from __future__ import annotations

import time

import numpy as np
from robocal.solver.compensate import Compensation, Model, compensate
from robocal.solver.kinematics import Layout

from .formats.errors import InputError
from .formats.model_json import ModelFile, read_model
from .formats.targets_csv import Targets, read_targets

TCP_NAME = "TCP"  # the virtual SMR's name in targets.csv when a tool centre point is given
MAX_ERROR_MM = 0.1  # a pose the model cannot bring closer than this is refused as unreachable


def solver_model(model: ModelFile, tcp=None) -> Model:
    """The model file as the solver takes it; with tcp (3,) mm in the flange frame, its one
    virtual SMR `TCP` in place of the SMRs."""
    if tcp is None:
        lay, x = model.layout()
    else:
        lay = Layout(model.robot, model.base, (TCP_NAME,))
        x = lay.initial(np.asarray(tcp, dtype=float).reshape(1, 3))
    return Model(lay, x, list(model.extensions), model.nominal or model.robot)


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
    targets.csv; tcp (3,) mm in the flange frame makes `TCP` the one target. InputError on bad
    input or an unreachable pose (nothing is written here either way)."""
    model = read_model(model_path)
    names = (TCP_NAME,) if tcp is not None else tuple(model.targets)
    targets = read_targets(targets_path, model.robot, names)
    res = compensate_targets(model, targets, tcp, max_error_mm)
    return targets.pose_ids, np.rad2deg(res.q), res.error_mm


def run(model_path, targets_path, out_path, tcp=None, max_error_mm: float = MAX_ERROR_MM):
    """Compensate and write joints.csv; returns a summary dict for the command's line."""
    from .formats.targets_csv import write_joints

    t0 = time.perf_counter()
    ids, q_deg, err = compensate_file(model_path, targets_path, tcp, max_error_mm)
    write_joints(out_path, ids, q_deg, err)
    return {
        "poses": len(ids),
        "worst_mm": float(err.max()),
        "rms_mm": float(np.sqrt(np.mean(err**2))),
        "seconds": time.perf_counter() - t0,
    }
