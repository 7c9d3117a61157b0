"""The bodies of a model's quick checks: one check's result, the history, the line's health."""

from __future__ import annotations

import datetime as dt
from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field

from robocal.server.checks.plan import DEFAULT_POSES, MAX_POSES, MIN_POSES
from robocal.server.formats.fields import Whole

from .schemas import Real

Verdict = Literal["ok", "watch", "recalibrate"]
VERDICT = (
    "ok; watch (a change that may be scatter: check again soon); recalibrate (the model no "
    "longer describes the arm, judged over the history)"
)

# The model's own verdict beside a check's: "ok" says the arm still matches the model, not
# that the model was fit to deploy (a nominal one is not)
DEPLOYABLE = Field(
    description="the model's own verdict (its validation block): a check judges only "
    "whether the arm still matches the model, not whether the model was fit to deploy"
)
NOT_DEPLOYABLE = Field(description="why the model is not deployable; [] if it is")


class CheckPublic(BaseModel):
    """One check as `robocal check` writes check.json (FORMATS section 8), and its job."""

    job_id: int
    model_sha256: str
    poses: int = Field(description="poses of the check with at least one reading")
    rms_mm: float = Field(description="3-D RMS of the readings' error against the model")
    max_mm: float
    expected_rms_mm: float = Field(description="the model's held-out error (noise floor at least)")
    verdict: Verdict = Field(description=VERDICT)
    reason: str = Field(description="one sentence a person can check; the cause where known")
    history: int = Field(description="checks of this model, this one included")
    change_mm: float | None = Field(
        description="RMS change from the model's first checks (null: nothing to compare with)"
    )
    scatter_mm: float | None = Field(description="the scatter between checks it was judged by")
    change_score: float = Field(description="normal score of the change")
    cusum: float = Field(description="the change scores accumulated over the history")
    cause: str | None = Field(
        description="rigid, joint N, scale, payload or unknown, when recalibrate; else null"
    )
    warnings: list[str] = Field(
        default_factory=list,
        description="what `robocal check` says on stderr beside the verdict (not in check.json): "
        "a backlash model's approach directions taken from the rows' order",
    )
    deployable: bool = DEPLOYABLE
    not_deployable: list[str] = NOT_DEPLOYABLE


class CheckEntry(BaseModel):
    """One stored check of the history, with the limits its figures were judged by."""

    id: int
    checked_at: dt.datetime
    source: str = Field(description="the uploaded file's name")
    poses: int
    rms_mm: float
    max_mm: float
    expected_rms_mm: float
    watch_rms_mm: float = Field(description="the RMS at which the level alone says watch")
    recalibrate_rms_mm: float = Field(
        description="the RMS at which the level alone says recalibrate"
    )
    change_score: float
    cusum: float
    verdict: Verdict
    reason: str


class CheckHistory(BaseModel):
    """A model's checks, oldest first, and the accumulated change's limits."""

    job_id: int
    model_sha256: str
    cusum_watch: float = Field(description="the accumulated change at which it says watch")
    cusum_recalibrate: float = Field(description="... and recalibrate")
    checks: list[CheckEntry]


class ModelHealth(BaseModel):
    """Whether the deployed model still holds, by its latest check: the production line's view."""

    job_id: int
    model_sha256: str
    checked: bool = Field(description="false: the model was never checked")
    verdict: Verdict | None = Field(description=f"{VERDICT}; null when never checked")
    reason: str
    checked_at: dt.datetime | None
    history: int = Field(description="checks of this model")
    rms_mm: float | None
    expected_rms_mm: float | None
    deployable: bool = DEPLOYABLE
    not_deployable: list[str] = NOT_DEPLOYABLE


class CheckRunCreate(BaseModel):
    """A check of the model to run on the service's cell: its check poses (those of the model's
    first check, else planned), as `robocal acquire --check`."""

    model_config = ConfigDict(extra="forbid")
    # the bounds before Whole: after it pydantic leaves them out of the JSON schema's numbers
    cell_id: str | None = Field(
        None,
        max_length=64,
        description="the cell it runs on (null: the one the model's campaign was measured on)",
    )
    poses: Annotated[int, Field(ge=MIN_POSES, le=MAX_POSES), Whole] | None = Field(
        None,
        description="poses to plan (null: those of the model's first check, else "
        f"{DEFAULT_POSES} planned); a model's later checks measure its first check's",
    )
    seed: Annotated[int, Field(ge=0, le=2**32 - 1), Whole] | None = Field(
        None,
        description="the simulated cell's arm (null: that of the model's own campaign)",
    )
    pause_s: Real = Field(10.0, ge=0.0, le=600.0)


class CheckRunPublic(BaseModel):
    """A check started on the cell (follow its campaign; judged into the history once done), or
    a check measured earlier and judged now."""

    job_id: int
    campaign_id: int
    campaign_url: str = Field(description="GET it for the run's progress and, once done, verdict")
    started: bool = Field(description="false: nothing run now, a done check campaign judged")
    note: str
    check: CheckPublic | None = Field(description="the judged check, when started is false")
