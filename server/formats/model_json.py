"""The calibrated model file (`model.json`, FORMATS.md section 3)."""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from solver.kinematics import Layout
from solver.robot import Robot

from .cell_json import robot_from_json, robot_to_json
from .files import atomic_write_text, read_text
from .json_doc import JsonDoc

SCHEMA = 1


@dataclass
class ModelFile:
    """What a model file says: the calibrated robot, base, SMRs, extensions and provenance."""

    robot: Robot
    base: np.ndarray
    targets: dict[str, np.ndarray]
    nominal: Robot | None = None
    extensions: list = field(default_factory=list)
    meta: dict = field(default_factory=dict)

    def layout(self) -> tuple[Layout, np.ndarray]:
        """The kinematic layout and parameter vector that reproduce this model's predictions."""
        names = tuple(self.targets)
        lay = Layout(self.robot, self.base, names)
        return lay, lay.initial(np.array([self.targets[n] for n in names]))


def file_digest(path) -> str:
    """sha256 of a file, so a model records exactly which data it was fitted on."""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def write_json_atomic(path, obj) -> None:
    """Write JSON through a temporary file so a crash never leaves half a file."""
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(path, json.dumps(obj, indent=2) + "\n")


def model_to_json(model: ModelFile) -> dict:
    return {
        "schema": SCHEMA,
        "robot": robot_to_json(model.robot),
        "nominal_robot": robot_to_json(model.nominal) if model.nominal is not None else None,
        "base": np.asarray(model.base).round(9).tolist(),
        "targets": {k: np.asarray(v).round(6).tolist() for k, v in model.targets.items()},
        "extensions": model.extensions,
        "created": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        **model.meta,
    }


def write_model(path, model: ModelFile) -> None:
    write_json_atomic(path, model_to_json(model))


def read_model(path) -> ModelFile:
    """Read a model file; refuse a malformed one with file:line:column and the field."""
    doc, obj = JsonDoc.parse(path, read_text(path))
    doc.object(obj, ())
    if obj.get("schema") != SCHEMA:
        raise doc.error(("schema",), f"expected schema {SCHEMA}, found {obj.get('schema')!r}")
    robot = robot_from_json(doc.require(obj, "robot", ()), doc, ("robot",))
    nominal = None
    if obj.get("nominal_robot") is not None:
        nominal = robot_from_json(obj["nominal_robot"], doc, ("nominal_robot",))
    rows = doc.array(doc.require(obj, "base", ()), ("base",), 4)
    base = np.array([[doc.number(v, ("base", i, j)) for j, v in
                      enumerate(doc.array(r, ("base", i), 4))] for i, r in enumerate(rows)])
    targets = {}
    for k, v in doc.object(doc.require(obj, "targets", ()), ("targets",)).items():
        at = ("targets", k)
        targets[k] = np.array([doc.number(c, (*at, i)) for i, c in enumerate(doc.array(v, at, 3))])
    if not targets:
        raise doc.error(("targets",), "at least one target is needed")
    extensions = doc.array(obj.get("extensions", []), ("extensions",))
    meta = {k: v for k, v in obj.items()
            if k not in ("schema", "robot", "nominal_robot", "base", "targets", "extensions")}
    return ModelFile(robot, base, targets, nominal, list(extensions), meta)
