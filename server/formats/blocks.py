"""The result blocks (fit, uncertainty, identified parameters, validation, diagnosis,
unexplained) as one pydantic document each: model.json and report.json hold them, the API
answers with them and the printers read them; nothing reads them by string key elsewhere."""

from __future__ import annotations

from typing import Annotated, Any, Literal

from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    PlainSerializer,
    PlainValidator,
    PrivateAttr,
    SerializerFunctionWrapHandler,
    ValidationError,
    ValidatorFunctionWrapHandler,
    WithJsonSchema,
    field_serializer,
    model_serializer,
    model_validator,
)
from pydantic_core import PydanticCustomError

NO_VERDICT = "the model has no validation verdict (written before the guard); calibrate again"


def _figure(value):
    # kept as written: an int stays an int and a NaN a NaN, so a block written, read and
    # written again is the same text
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise PydanticCustomError("float_type", "Input should be a valid number")
    return value


# A figure the program wrote (any JSON number, NaN where the writer had one)
Figure = Annotated[
    float,
    PlainValidator(_figure),
    PlainSerializer(lambda v: v),  # as read: an int is no float to warn about
    WithJsonSchema({"type": "number"}),
]
# A figure a reader acts on: a finite JSON number
Statistic = Annotated[float, Field(strict=True, allow_inf_nan=False)]
# An error or noise figure a reader acts on (an RMS, a maximum, mm): finite, never negative
Error = Annotated[float, Field(strict=True, ge=0, allow_inf_nan=False)]


def _magnitude(value):
    value = _figure(value)
    if value < 0:  # False for NaN: the program writes one where it had nothing to compute
        raise PydanticCustomError(
            "greater_than_equal", "Input should be greater than or equal to {ge}", {"ge": 0}
        )
    return value


# A size the program wrote, never negative (a condition number: NaN for the nominal method's)
Magnitude = Annotated[
    float,
    PlainValidator(_magnitude),
    PlainSerializer(lambda v: v),
    WithJsonSchema({"type": "number", "minimum": 0}),
]
Text = Annotated[str, Field(strict=True)]
Count = Annotated[int, Field(strict=True)]


class Block(BaseModel):
    """A block the program writes and reads back: its keys typed, any other kept as written."""

    model_config = ConfigDict(extra="allow", populate_by_name=True)

    def to_json(self) -> dict[str, Any]:
        """The block as written: the keys it was given, in its fields' order."""
        return self.model_dump(by_alias=True, exclude_unset=True)


class Ordered(Block):
    """A block the solver writes as a dict (a diagnosis report's): its keys written in the order
    they were given, then in the order set (the figures' names after the solver's keys)."""

    _order: tuple[str, ...] = PrivateAttr(())

    @model_validator(mode="wrap")
    @classmethod
    def _given_order(cls, data: Any, handler: ValidatorFunctionWrapHandler) -> Any:
        obj = handler(data)
        if isinstance(data, dict) and isinstance(obj, Ordered):
            obj._order = tuple(data)
        return obj

    def __setattr__(self, name: str, value: Any) -> None:
        super().__setattr__(name, value)
        if not name.startswith("_"):
            field = type(self).model_fields.get(name)
            key = field.alias if field is not None and field.alias else name
            if key not in self._order:
                self._order = (*self._order, key)

    @model_serializer(mode="wrap")
    def _in_order(self, handler: SerializerFunctionWrapHandler) -> dict[str, Any]:
        out = handler(self)
        return {**{k: out[k] for k in self._order if k in out}, **out}


class Fit(Block):
    """model.json's `fit`: the fit's own figures (on the readings it was fitted on)."""

    F_mm2: dict[str, Error] | None = Field(None, description="per SMR, the objective F_i")
    rmse_phi_mm: Error | None = None
    rmse_mm: Error | None = Field(None, description="the fit's RMS error per reading")
    ap_max_mm: Error | None = None
    condition_number: Magnitude | None = None
    fixed_parameters: dict[str, Text] | None = Field(
        None, description="parameters held fixed, and why"
    )
    iterations: Count | None = None
    seconds: Error | None = None
    readings_used: Count | None = None
    excluded_readings: list[dict[str, Any]] | None = Field(
        None, description="readings left out as gross errors"
    )
    screening: dict[str, Any] | None = None


class Uncertainty(Block):
    """model.json's `uncertainty`: the named parameters' standard errors and how estimated."""

    estimator: Text | None = Field(None, description="how the covariance was estimated")
    poses: Count | None = None
    units: Text | None = None
    frames: Text | None = None
    standard_errors: dict[str, Statistic | None] | None = Field(
        None, description="per parameter, mm or degrees (null: held fixed)"
    )
    null: Text | None = None
    position: dict[str, Any] | None = Field(
        None, description="the position uncertainty's covariance and joint scatter"
    )


class ParameterRow(Block):
    """One identified parameter in edge units (mm, degrees)."""

    parameter: Text = Field(description="its name: a1, theta2, base_x, A_y...")
    group: Literal["joint", "base", "smr"] | None = None
    kind: Text | None = Field(None, description="theta, d, a, alpha, beta; x, y, z, rz, ry, rx")
    joint: Count | None = Field(None, description="joints from 1 (group joint)")
    target: Text | None = Field(None, description="the SMR (group smr)")
    unit: Literal["mm", "deg"] | None = None
    nominal: Statistic | None = Field(None, description="the cell's value, mm or degrees")
    calibrated: Figure | None = None
    change: Figure | None = Field(None, description="calibrated - nominal")
    standard_error: Statistic | None = Field(
        None, description="null where held fixed; the posterior's where shrunk"
    )
    status: Literal["identified", "shrunk toward nominal", "held fixed"] | None = None


class FixedParameter(Block):
    parameter: Text
    why: Text = Field(description="unidentifiable or redundant with the parameters named")


class ShrunkParameter(Block):
    parameter: Text
    data_share: Figure = Field(
        ge=0,
        le=1,
        description="the share of its estimate from the data (1 - posterior / prior variance); "
        "the rest is the prior's pull toward nominal",
    )
    why: Text = Field(description="why the data identifies it too little")


class Correlation(Block):
    a: Text
    b: Text
    r: Figure = Field(ge=-1, le=1)


class Identified(Block):
    """The identified-parameter table of a calibration."""

    convention: Text | None = None
    units: Text | None = None
    frames: Text | None = None
    estimator: Text | None = Field(None, description="how the standard errors were estimated")
    rows: list[ParameterRow] = Field([], description="one per parameter")
    fixed: list[FixedParameter] = Field([], description="held fixed, and why")
    shrunk: list[ShrunkParameter] = Field(
        [], description="seen too little to identify: shrunk toward nominal by the prior, and why"
    )
    prior: Text | None = Field(
        None, description="the prior on the geometry's change from nominal, and its weight"
    )
    condition_number: Figure | None = Field(
        None, description="of the identified parameters (shrunk and held ones left out)"
    )
    correlations: list[Correlation] = Field([], description="the strongest |r|, largest first")


class ValidationLimits(Block):
    min_equations_per_parameter: Figure
    noise_floor_fraction: Figure
    max_condition_number: Figure
    max_holdout_ratio: Figure


class HeldOut(Block):
    """A calibration's errors on readings it was not fitted on: a held-out campaign (a job's) or
    file (`robocal calibrate --held-out`), mm per reading."""

    file: Text | None = None
    campaign_id: Count | None = None
    poses: Count
    readings: Count
    rms_mm: Error | None = Field(description="the calibrated model's 3-D RMS error")
    max_mm: Error | None
    nominal_rms_mm: Error | None = Field(description="the nominal model's, registered on them")
    warning: Text | None = Field(None, description="why the figures may not be of this cell")


class Validation(Block):
    """The verdict: whether the data supports the model and it may be deployed, why not, and the
    held-out figure (the headline) beside the fit's; a block without `deployable` (written
    before the guard) is no verdict, and `of` reads it as not deployable."""

    deployable: Annotated[bool, Field(strict=True)] | None = Field(
        None,
        description="false, or missing: compensate and export refuse the model unless forced",
    )
    reasons: tuple[Text, ...] = Field((), description="why not deployable, one sentence each")
    summary: Text | None = Field(
        None, description="the accuracy to expect on new poses, in one sentence"
    )
    tolerance_mm: Annotated[float, Field(strict=True, gt=0, allow_inf_nan=False)] | None = Field(
        None,
        description="the accuracy the application needs (--tolerance-mm, else the cell's "
        "`tolerance_mm`), mm; null: none given",
    )
    holdout_rms_mm: Error | None = Field(None, description="the held-out RMS, mm")
    holdout_max_mm: Error | None = Field(None, description="the held-out maximum, mm")
    fit_rms_mm: Error | None = None
    holdout: Text | None = Field(None, description="how the held-out figures were had")
    condition_number: Figure | None = None
    equations: Count | None = None
    free_parameters: Count | None = None
    noise_floor_mm: Error | None = None
    noise_floor_source: Text | None = None
    unsupported_poses: list | None = Field(None, description="poses the others cannot do without")
    limits: ValidationLimits | None = None
    nominal_rms_mm: Error | None = Field(
        None, description="the nominal model's RMS on the fitted readings, base and SMRs registered"
    )
    nominal_holdout_rms_mm: Error | None = Field(
        None,
        description="the nominal model's held-out RMS (leave-one-pose-out): a model past it is "
        "not deployable",
    )
    warnings: tuple[Text, ...] = Field(
        (), description="what deserves a look but leaves the model deployable, one sentence each"
    )
    held_out: HeldOut | None = Field(
        None, description="the errors on a separate held-out campaign or file, when there is one"
    )

    @field_serializer("reasons", "warnings")
    def _as_list(self, sentences: tuple[str, ...]) -> list[str]:
        return list(sentences)  # a JSON array, as read back

    @classmethod
    def of(cls, block: Validation | dict | None) -> Validation:
        """The verdict of a `validation` block (as model.json and report.json hold it); without
        one, or without its `deployable`, the model is not deployable."""
        if isinstance(block, dict):
            try:
                block = cls.model_validate(block)
            except ValidationError:
                block = None
        if block is None or block.deployable is None:
            return cls(deployable=False, reasons=(NO_VERDICT,))
        if not block.deployable and not block.reasons:
            why = ("its validation says not deployable without a reason",)
            return block.model_copy(update={"reasons": why})
        return block

    def refusal(self) -> str | None:
        """Why the model must not be deployed, in one line; None if it may be."""
        if self.deployable:
            return None
        return "the model is not deployable: " + "; ".join(self.reasons or (NO_VERDICT,))


class Score(Block):
    """A model's held-out figures in a diagnosis (its baseline, its final model)."""

    model: str = Field(description="geometric, then each effect: geometric+joint_compliance(2)")
    holdout_rmse_mm: Error
    holdout_max_mm: Error


class Diagnosis(Block):
    """model.json's `diagnosis` (a diagnosis's final model): its report's final figures, noise
    floor and the readings it excluded."""

    final: Score
    noise_floor_mm: Figure | None = None
    noise_floor_source: Text | None = None
    outliers: list[dict[str, Any]] | None = None
    # per joint, the [min, max] deg its campaign covered: the extensions hold within it
    joint_range_deg: list[list[float]] | None = None


class Covariate(Ordered):
    name: str
    strength: float
    reading: str


class Unexplained(Ordered):
    """What the final model leaves above the noise floor, and the covariates it follows."""

    holdout_rmse_mm: float
    share_of_baseline_mse: float | None
    covariates: list[Covariate]
    per_pose_share: float | None = None
    per_pose_reading: str | None = None
    reading: str | None = Field(None, description="the finding in one sentence")


class QuotedScore(Block):
    holdout_rmse_mm: Figure | None = None


class QuotedDiagnosis(Block):
    final: QuotedScore | None = None


class ModelQuote(Block):
    """What a verification record quotes of its model's blocks: the diagnosis's final held-out
    figure (a diagnosis's model) and the verdict's deployable, tolerance and held-out RMS."""

    diagnosis: QuotedDiagnosis | None = None
    validation: Validation | None = None

    def holdout_rms_mm(self) -> float | None:
        """The held-out RMS (mm) as the diagnosis stated it, else as the verdict did (a
        calibration's leave-one-pose-out figure); None if neither did, or without a verdict."""
        final = self.diagnosis.final if self.diagnosis else None
        if final is not None and final.holdout_rmse_mm is not None:
            return final.holdout_rmse_mm
        return Validation.of(self.validation).holdout_rms_mm
