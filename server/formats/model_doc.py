"""The shape of `model.json` (spec section 3) as pydantic models."""

from __future__ import annotations

from typing import Annotated, Literal

import numpy as np
from pydantic import (
    ConfigDict,
    Field,
    PrivateAttr,
    TypeAdapter,
    ValidationError,
    field_validator,
    model_validator,
)

from robocal.solver.effects import Extension
from robocal.solver.vocabulary import KINDS

from .blocks import Diagnosis, Fit, Identified, Uncertainty, Validation
from .cell_doc import RigidTransform, RobotDoc, check_targets
from .fields import TARGET_NAME_PATTERN, Doc, Integer, Label, Number, Point, Whole, located

SCHEMA = 1
# The typed reads an effect's `from_json` asks for (`read.number(key)` ...), by their types.
_READS = {
    "number": TypeAdapter(Number),
    "integer": TypeAdapter(Integer),
    "string": TypeAdapter(Label),
    "vector": TypeAdapter(list[Number]),
}


class _Reader:
    """The fields of one extension object as an effect's `from_json` reads them."""

    def __init__(self, obj: dict):
        self.obj = obj

    def error(self, key, message):
        return located(message, key)

    def has(self, key) -> bool:
        return key in self.obj

    def __getattr__(self, kind):
        if kind not in _READS:
            raise AttributeError(kind)
        return lambda key: self._read(kind, key)

    def _read(self, kind, key):
        from .json_doc import explain

        if key not in self.obj:
            raise located(f"missing key {key!r}")
        try:
            value = _READS[kind].validate_python(self.obj[key])
        except ValidationError as e:
            at, message, as_key = explain(e.errors()[0])
            raise located(message, key, *at, key=as_key) from None
        return np.array(value, dtype=float) if kind == "vector" else value


class ExtensionDoc(Doc):
    """One model extension: its effect, place (joints from 1), coefficients and the effect's own
    fields (see the effect vocabulary)."""

    model_config = ConfigDict(extra="allow")
    name: str = Field(json_schema_extra={"enum": list(KINDS)})
    # the bound inside the type: after Integer's check, the schema would say "ge", not "minimum"
    joint: Annotated[int, Field(ge=1), Whole] | None = Field(
        None, description="joints are numbered from 1"
    )
    coef: list[Number] = Field(description="model-internal coefficients")
    parameters: dict | None = Field(None, description="the coefficients in degrees, ppm and mm")
    coef_standard_errors: list | None = None
    uncertainty: dict | None = None
    _extension: Extension = PrivateAttr()

    @model_validator(mode="after")
    def _build(self):
        kind = KINDS.get(self.name)
        if kind is None:
            raise located(f"unknown extension {self.name!r} (known: {', '.join(KINDS)})", "name")
        if kind.is_joint and self.joint is None:
            raise located("missing key 'joint'")
        joint = self.joint - 1 if kind.is_joint else None
        own = kind.from_json(_Reader(self.model_extra or {}))
        ext = Extension(self.name, joint=joint, coef=np.array(self.coef, dtype=float), **own)
        if len(ext.coef) != ext.n_params:
            raise located(f"expected {ext.n_params} coefficients", "coef")
        self._extension = ext
        return self

    @property
    def extension(self) -> Extension:
        return self._extension


class ModelDoc(Doc):
    """A model.json: the calibrated robot, base, SMRs, extensions; other keys (method, data,
    fit statistics, created) are kept as written."""

    model_config = ConfigDict(extra="allow", title="model.json")
    schema_: Annotated[Literal[1], Whole] = Field(alias="schema")
    robot: RobotDoc
    nominal_robot: RobotDoc | None = None
    base: RigidTransform = Field(description="the robot base in the tracker frame, mm")
    targets: dict[str, Point] = Field(
        description="SMR positions in the flange frame, mm",
        json_schema_extra={
            "minProperties": 1,
            "propertyNames": {"pattern": f"^{TARGET_NAME_PATTERN}$"},
        },
    )
    extensions: list[ExtensionDoc] = []
    created: Label | None = None
    fit: Fit | None = Field(None, description="the fit's statistics")
    uncertainty: Uncertainty | None = Field(
        None, description="the parameters' standard errors (mm, degrees) and how estimated"
    )
    identified: Identified | None = Field(
        None,
        description="a calibration's identified parameters: `rows` (per parameter: group, "
        "nominal, calibrated, change, standard_error in mm and degrees), `fixed` (held and "
        "why), `condition_number`, `correlations` (the strongest |r|)",
    )
    validation: Validation | None = Field(
        None,
        description="whether the model may be deployed: `deployable` (false whenever the "
        "held-out error exceeds `tolerance_mm`), `reasons`, `summary`, "
        "`holdout_rms_mm` (leave-one-pose-out, the headline), `fit_rms_mm`, "
        "`condition_number`, `noise_floor_mm`, `limits`; `held_out` with the errors on a "
        "separate held-out campaign or file, when there is one",
    )
    diagnosis: Diagnosis | None = Field(
        None, description="a diagnosis's final model: its final figures, noise floor, outliers"
    )

    @field_validator("targets")
    @classmethod
    def _targets(cls, targets: dict) -> dict:
        return check_targets(targets)

    @model_validator(mode="after")
    def _check(self):
        n = self.robot.robot.n_joints
        for i, e in enumerate(self.extensions):
            if e.joint is not None and e.joint > n:
                raise located(
                    f"joint {e.joint} is not one of the robot's joints 1 to {n}",
                    "extensions",
                    i,
                    "joint",
                )
            ext = e._extension
            if ext.gravity is not None and ext.joint is not None:
                # the gravity basis has four columns (mass, three moments) per link the joint moves
                want = 4 * (n - ext.joint)
                stored = (("masses", ext.masses), ("gravity_terms_total", ext.keep))
                sizes = [(k, v) for k, v in stored if v is not None] or [stored[1]]
                for key, v in sizes:
                    got = 0 if v is None else len(v)
                    if got == want:
                        continue
                    raise located(
                        f"expected {want} values for joint {e.joint}'s {n - ext.joint} links, "
                        f"got {got}",
                        "extensions",
                        i,
                        key,
                    )
        return self
