"""The answers of the model routes that describe a model: its identified parameters and its
validation (model.json's `identified` and `validation` blocks)."""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, Field


class ParameterRow(BaseModel):
    """One identified parameter in edge units (mm, degrees)."""

    parameter: str = Field(description="e.g. theta2, base_x, A_y")
    group: Literal["joint", "base", "smr"]
    kind: str = Field(description="theta, d, a, alpha, beta; x, y, z, rz, ry, rx")
    joint: int | None = Field(None, description="joints from 1 (group joint)")
    target: str | None = Field(None, description="the SMR (group smr)")
    unit: Literal["mm", "deg"]
    nominal: float | None = Field(description="the cell's nominal value, if it has one")
    calibrated: float
    change: float | None = Field(description="calibrated - nominal")
    standard_error: float | None = Field(description="none where held fixed")
    status: Literal["identified", "held fixed"]


class FixedParameter(BaseModel):
    parameter: str
    why: str = Field(description="unidentifiable or redundant with the parameters named")


class Correlation(BaseModel):
    a: str
    b: str
    r: float = Field(ge=-1, le=1)


class Identified(BaseModel):
    """The identified-parameter table of a calibration."""

    convention: str
    units: str
    frames: str
    estimator: str = Field(description="how the standard errors were estimated")
    rows: list[ParameterRow]
    fixed: list[FixedParameter]
    condition_number: float | None
    correlations: list[Correlation] = Field(description="the strongest |r|, largest first")


class ValidationLimits(BaseModel):
    min_equations_per_parameter: float
    noise_floor_fraction: float
    max_condition_number: float
    max_holdout_ratio: float


class HoldoutSummary(BaseModel):
    """A calibration's errors on readings it was not fitted on: a held-out campaign (a job's) or
    file (`robocal calibrate --held-out`), mm per reading."""

    campaign_id: int | None = None
    file: str | None = None
    poses: int
    readings: int
    rms_mm: float | None = Field(description="the calibrated model's 3-D RMS error")
    max_mm: float | None
    nominal_rms_mm: float | None = Field(description="the nominal model's, registered on them")
    warning: str | None = Field(None, description="why the figures may not be of this cell")


class Validation(BaseModel):
    """Whether the data supports the model; held-out RMS is the headline figure."""

    deployable: bool
    reasons: list[str] = Field(description="each limit the fit breaks, with its figures")
    warnings: list[str] = Field(
        [], description="what deserves a look but leaves the model deployable"
    )
    summary: str | None = Field(None, description="the accuracy to expect on new poses")
    tolerance_mm: float | None = Field(None, description="the accuracy the application needs")
    holdout_rms_mm: float | None = Field(description="leave-one-pose-out RMS per reading")
    holdout_max_mm: float | None
    fit_rms_mm: float | None
    nominal_rms_mm: float | None = Field(
        None, description="the nominal model's RMS on the fitted readings, base and SMRs registered"
    )
    holdout: str
    condition_number: float | None
    equations: int
    free_parameters: int
    noise_floor_mm: float | None
    noise_floor_source: str
    unsupported_poses: list = Field(description="poses the others cannot do without")
    limits: ValidationLimits
    held_out: HoldoutSummary | None = Field(
        None, description="the errors on a separate held-out campaign, when there is one"
    )


class ModelParameters(BaseModel):
    """A done job's identified parameters and its validation (none for models written before
    them, or a diagnosis's extended model: its table is then rebuilt from model.json)."""

    job_id: int
    method: str | None
    identified: Identified
    validation: Validation | None


class ValidationSummary(BaseModel):
    """A calibration job's verdict (GET /api/models/{id}/parameters has the whole)."""

    deployable: bool
    reasons: list[str]
    warnings: list[str] = Field(
        [], description="what deserves a look but leaves the model deployable"
    )
    summary: str | None = Field(None, description="the accuracy to expect on new poses")
    holdout_rms_mm: float | None
    holdout_max_mm: float | None = None
    fit_rms_mm: float | None
    tolerance_mm: float | None = Field(None, description="the accuracy the application needs")
    noise_floor_mm: float | None = None
    noise_floor_source: str | None = Field(None, description="where the noise floor comes from")
