"""The calibrated model file (`model.json`, FORMATS.md section 3)."""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, Generic, TypeVar

import numpy as np

from robocal.solver.effects import Extension
from robocal.solver.kinematics import Layout
from robocal.solver.robot import Robot

from .blocks import Block, Diagnosis, Fit, Identified, Uncertainty, Validation
from .cell_json import robot_to_json
from .files import atomic_write_text, read_text
from .json_doc import JsonDoc
from .model_doc import SCHEMA, ModelDoc

# what ModelFile holds apart from `meta`
MODEL_KEYS = ("schema", "robot", "nominal_robot", "base", "targets", "extensions")
# the result blocks of `meta`, typed (formats.blocks)
BLOCKS = {
    "fit": Fit,
    "uncertainty": Uncertainty,
    "identified": Identified,
    "validation": Validation,
    "diagnosis": Diagnosis,
}


B = TypeVar("B", bound=Block)


class _Slot(Generic[B]):
    """A typed result block of a model file, read and set as an attribute; `meta` keeps it in
    the order the file had it (or it was set in), so a file written again is the same text."""

    def __init__(self, kind: type[B]):
        self.kind = kind

    def __set_name__(self, owner, name: str) -> None:
        self.name = name

    def __get__(self, model, owner=None) -> B | None:
        return model.meta.get(self.name)

    def __set__(self, model, block: B) -> None:
        if not isinstance(block, self.kind):
            raise TypeError(f"model.json's {self.name} must be a {self.kind.__name__}")
        model.meta[self.name] = block


@dataclass
class ModelFile:
    """What a model file says: the calibrated robot, base, SMRs, extensions and provenance."""

    robot: Robot
    base: np.ndarray
    targets: dict[str, np.ndarray]
    nominal: Robot | None = None
    extensions: list = field(default_factory=list)
    # provenance (method, data, qp...) as written, and the result blocks as typed documents
    meta: dict = field(default_factory=dict)
    parameters: list | None = None  # per extension, its parameters in edge units (for people)
    # per extension: {"coef_standard_errors": [...], "uncertainty": {parameter: standard error}}
    extension_errors: list | None = None

    # not annotated: slots, not dataclass fields
    fit = _Slot(Fit)
    uncertainty = _Slot(Uncertainty)
    identified = _Slot(Identified)
    validation = _Slot(Validation)
    diagnosis = _Slot(Diagnosis)

    @property
    def method(self) -> str | None:
        """How it was fitted (minimax, ls-sum+extensions...); None if the file does not say."""
        return self.meta.get("method")

    @property
    def verdict(self) -> Validation:
        """Its `validation` block as the guard reads it: what compensate, export, the service
        and the page act on (none, or without `deployable`: not deployable)."""
        return Validation.of(self.validation)

    def layout(self) -> tuple[Layout, np.ndarray]:
        """The kinematic layout and parameter vector that reproduce this model's predictions."""
        names = tuple(self.targets)
        lay = Layout(self.robot, self.base, names)
        return lay, lay.initial(np.array([self.targets[n] for n in names]))


def extension_to_json(
    ext: Extension, parameters: dict | None = None, errors: dict | None = None
) -> dict:
    """An extension as stored: its kind and place (joints from 1), its own fields (the kind's
    `to_json`), coefficients, readable parameters, standard errors."""
    out: dict[str, Any] = {"name": ext.name}
    if ext.joint is not None:
        out["joint"] = ext.joint + 1
    out.update(ext.kind.to_json(ext))
    # model-internal coefficients (rad per basis unit, or per reading scalar); `parameters` says
    # the same in degrees, ppm and mm
    out["coef"] = np.asarray(ext.coef, dtype=float).tolist()
    if parameters is not None:
        out["parameters"] = parameters
    out.update(errors or {})
    return out


def uncertainty_to_json(errors, names) -> Uncertainty:
    """The standard errors of the named parameters of a fit (solver.uncertainty.ParameterErrors)
    as model.json states them (extension coefficients go with their extension)."""
    se = errors.standard_errors()
    return Uncertainty(
        estimator=errors.estimator,
        poses=errors.poses,
        units="mm; degrees for theta, alpha, beta and base_rz, base_ry, base_rx",
        frames="base_x/y/z and base_rz/ry/rx along and about the calibrated base frame's "
        "axes; SMR positions in the flange frame",
        standard_errors={n: se[n] for n in names},
        null="held fixed: not identifiable from this model (see fit.fixed_parameters)",
    )


def extension_errors(errors) -> list[dict]:
    """Per extension (solver.fit_errors.ExtendedErrors), its coefficients' standard errors (in the
    coefficients' own units) and its parameters' (edge units)."""
    return [
        {"coef_standard_errors": c, "uncertainty": u}
        for c, u in zip(errors.coefficients, errors.effects)
    ]


def file_digest(path) -> str:
    """sha256 of a file, so a model records exactly which data it was fitted on."""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def to_plain(obj):
    """A JSON-safe copy: numpy scalars and arrays become Python numbers and lists, anything else
    unknown its text."""
    return json.loads(
        json.dumps(obj, default=lambda v: v.tolist() if hasattr(v, "tolist") else str(v))
    )


def write_json_atomic(path, obj) -> None:
    """Write JSON through a temporary file so a crash never leaves half a file."""
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(path, json.dumps(obj, indent=2) + "\n")


def model_to_json(model: ModelFile) -> dict:
    return {
        "schema": SCHEMA,
        "robot": robot_to_json(model.robot),
        "nominal_robot": robot_to_json(model.nominal) if model.nominal is not None else None,
        # every digit: a base rounded to 1e-9 is no longer a rotation, and at a tracker's
        # distances that would move a prediction (and the URDF export's match) by micrometres
        "base": np.asarray(model.base, dtype=float).tolist(),
        "targets": {k: np.asarray(v).round(6).tolist() for k, v in model.targets.items()},
        "extensions": [
            extension_to_json(e, p, u)
            for e, p, u in zip(
                model.extensions,
                model.parameters or [None] * len(model.extensions),
                model.extension_errors or [None] * len(model.extensions),
            )
        ],
        "created": datetime.now(UTC).isoformat(timespec="seconds"),
        **{k: v.to_json() if isinstance(v, Block) else v for k, v in model.meta.items()},
    }


def write_model(path, model: ModelFile) -> None:
    write_json_atomic(path, model_to_json(model))


def read_model(path) -> ModelFile:
    """Read a model file; refuse a malformed one with file:line:column and the field."""
    return parse_model(read_text(path), path)


def parse_model(text: str, path="<model>") -> ModelFile:
    """A model file's text as read_model reads it (a model kept elsewhere, in a record)."""
    doc, obj = JsonDoc.parse(path, text)
    m = doc.validate(ModelDoc, obj)
    extensions = [e.extension for e in m.extensions]
    stored = obj.get("extensions", [])
    parameters = [e.get("parameters") for e in stored] if extensions else None
    errors = (
        [{k: e[k] for k in ("coef_standard_errors", "uncertainty") if k in e} for e in stored]
        if extensions
        else None
    )
    return ModelFile(
        m.robot.robot,
        np.array(m.base, dtype=float),
        {k: np.array(v, dtype=float) for k, v in m.targets.items()},
        None if m.nominal_robot is None else m.nominal_robot.robot,
        extensions,
        {k: getattr(m, k) if k in BLOCKS else v for k, v in obj.items() if k not in MODEL_KEYS},
        parameters,
        errors,
    )


def joint_range_deg(q_rad: np.ndarray) -> list[list[float]]:
    """Per joint, the [min, max] deg of poses q_rad (m, n): the range a campaign covered."""
    q = np.degrees(np.asarray(q_rad, dtype=float))
    return np.round(np.stack([q.min(axis=0), q.max(axis=0)], axis=1), 3).tolist()


# How far past the joint range its campaign covered a pose may put a joint whose extensions
# correct it before a warning says so: a few degrees of a smooth correction is interpolation.
RANGE_MARGIN_DEG = 5.0


def extrapolated(model: ModelFile, q_rad: np.ndarray, pose_ids) -> str | None:
    """One sentence naming the poses (q_rad (m, n)) that put a joint the model's extensions
    correct outside the range its diagnosis measured (by more than RANGE_MARGIN_DEG), where the
    correction is extrapolated; None when every pose is inside (or the model does not say)."""
    ranges = model.diagnosis.joint_range_deg if model.diagnosis is not None else None
    joints = sorted({e.joint for e in model.extensions if e.is_joint})
    if not ranges or not joints or len(q_rad) == 0:
        return None
    q = np.degrees(np.asarray(q_rad, dtype=float))
    for j in joints:
        lo, hi = ranges[j]
        out = np.flatnonzero((q[:, j] < lo - RANGE_MARGIN_DEG) | (q[:, j] > hi + RANGE_MARGIN_DEG))
        if len(out):
            k = int(out[0])
            labels = ", ".join(e.label() for e in model.extensions if e.is_joint and e.joint == j)
            return (
                f"{len(out)} poses (first {pose_ids[k]!r}, q{j + 1} {q[k, j]:.1f} deg) lie outside "
                f"the q{j + 1} range the diagnosis measured ({lo:.1f} to {hi:.1f} deg): "
                f"{labels} there is extrapolated, not measured"
            )
    return None


def rows_as_motion(q_rad, time_s, prev_q, what: str) -> str | None:
    """One clause when the file's row order decides the direction of some poses' last motion
    (neither time_s nor prev_q for them; solver.motion) for `what` (the backlash that needs it),
    naming a joint the rows look sorted by; None when the data orders every pose."""
    from robocal.solver.motion import ordered_by_rows, sorted_joint

    q = np.atleast_2d(np.asarray(q_rad, dtype=float))
    count = ordered_by_rows(time_s, prev_q, len(q), q)
    if not count:
        return None
    n = q.shape[1]
    poses = "the poses" if count == len(q) - 1 else f"{count} poses"
    said = (
        f"the rows' order is taken as the order of motion for {poses} without time_s or "
        f"prev_q1..prev_q{n}: {what} takes the joints' approach directions from it, wrong if "
        "the file was sorted or merged after the fact"
    )
    if (sort := sorted_joint(q)) is not None:
        j, way = sort
        said += f" (q{j + 1} only {'rises' if way > 0 else 'falls'} down the rows: sorted?)"
    return said


def diagnosis_order(model: ModelFile, q_rad, time_s, prev_q) -> str | None:
    """rows_as_motion for a diagnosis whose final model has backlash (its approach directions
    came from the rows) or whose rows look sorted by a joint (the backlash it tested on every
    joint read directions a sort scrambles); None otherwise: a campaign in visit order without
    times, whose diagnosis named no backlash, is not warned about what did not matter."""
    from robocal.solver.motion import sorted_joint

    lost = [e.label() for e in model.extensions if e.name == "joint_backlash"]
    if not lost and sorted_joint(q_rad) is None:
        return None
    what = f"the diagnosed {', '.join(lost)}" if lost else "the backlash tested on each joint"
    return rows_as_motion(q_rad, time_s, prev_q, what)


def approach_unknown(model: ModelFile, q_rad, time_s, prev_q, pose_ids) -> str | None:
    """One sentence when the model has backlash and the data leaves its approach directions to
    the row order (rows_as_motion), and naming the poses (q_rad (m, n)) where a backlash joint has
    no direction of its last motion (the first pose visited, without prev_q; solver.motion), so
    that its backlash is not applied there; None when every pose's direction is from the data."""
    from robocal.solver.motion import last_motion

    lost = [e for e in model.extensions if e.name == "joint_backlash"]
    if not lost or len(q_rad) == 0:
        return None
    n = model.robot.n_joints
    labels = ", ".join(e.label() for e in lost)
    order = rows_as_motion(q_rad, time_s, prev_q, f"the model's {labels}")
    motion = last_motion(np.asarray(q_rad, dtype=float), time_s, prev_q)
    give = f"give prev_q1 ... prev_q{n}, the joints the arm comes from"
    for e in lost:
        none = np.flatnonzero(motion[:, e.joint] == 0)
        if len(none):
            b = abs(float(np.degrees(e.coef[0])))
            first = pose_ids[none[0]]
            who = (
                f"{len(none)} poses (first {first!r}) give"
                if len(none) > 1
                else f"pose {first!r} gives"
            )
            if order:  # the first row: one sentence for both, as they have one cause
                return (
                    f"{order}; at {who.removesuffix(' give').removesuffix(' gives')} (no motion "
                    f"before) joint {e.joint + 1}'s is unknown, its {b:.3g} deg not applied; {give}"
                )
            return (
                f"{who} no direction of joint {e.joint + 1}'s last motion (the first visited, "
                f"without prev_q): the model's {e.label()} ({b:.3g} deg) is not applied there; "
                + give
            )
    return f"{order}; {give}" if order else None
