"""Request and response bodies, one family per resource (Create / Public)."""

from __future__ import annotations

import datetime as dt
import difflib
import re
from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field, field_validator

from robocal.drivers.lifecycle import ACTIONS, STATES
from robocal.server.acquisition.planning import MAX_CANDIDATES, MAX_CHOICE_WORK
from robocal.server.formats.cell_doc import CellDoc, Tolerance
from robocal.server.formats.fields import Integer, Whole
from robocal.server.formats.limits import COORD_MAX_MM, PRINTABLE
from robocal.server.store.checks import ARM_MAX
from robocal.server.verify.run import CUBE_SIDE_MM, DIRECTIONS

from .model_schemas import HeldOut, Validation

# A request's unknown field is refused (422), never ignored: a misspelt option is no default.
REQUEST = ConfigDict(extra="forbid")
# Ids are SQLite rowids.
MAX_ID = 2**63 - 1
METHOD = r"^(minimax|ls-sum|ls-pose|nominal|ls-single(:[A-Za-z][A-Za-z0-9_]{0,15})?)$"
METHOD_NAMES = ("minimax", "ls-sum", "ls-single", "ls-pose", "nominal")
# the engine's states and the user's actions, listed in the OpenAPI; mypy takes only literals
# written out in a Literal
# A request's numbers and flags as JSON has them: pydantic's lax mode would take false for 0, true
# for 1 and "0.5" for 0.5 (Integer: a whole number, never true or "3")
Real = Annotated[float, Field(strict=True)]
Flag = Annotated[bool, Field(strict=True)]
State = Literal[STATES]  # type: ignore[valid-type]
Action = Literal[ACTIONS]  # type: ignore[valid-type]


class CellPublic(BaseModel):
    id: str
    simulated: bool = Field(description="false when the cell has real `devices`")
    cell: CellDoc = Field(description="the cell.json, every value spelled out")


class CampaignCreate(BaseModel):
    """A campaign to plan (as `robocal acquire` plans it), on the cell's real devices if it has
    `devices`, else on the simulated ones."""

    model_config = REQUEST
    name: str | None = Field(None, min_length=1, max_length=200, pattern=PRINTABLE)
    cell_id: str = Field("default", max_length=64)
    poses: Integer = Field(20, ge=3, le=5000)
    seed: Integer = Field(0, ge=0, le=2**32 - 1)
    settle: Literal["fixed", "adaptive"] = "fixed"
    pause_s: Real = Field(10.0, ge=0.0, le=600.0)
    order: Flag = False
    choose_from: Integer = Field(
        0,
        ge=0,
        le=MAX_CANDIDATES,
        description=(
            "choose `poses` of this many candidates by D-optimality (0: no choice); "
            f"poses x choose_from at most {MAX_CHOICE_WORK}"
        ),
    )
    beam_break_rate: Real = Field(0.0, ge=0.0, lt=1.0, description="simulated cell only")
    samples: Integer = Field(1000, ge=1, le=100_000)
    arm: str | None = Field(
        None,
        min_length=1,
        max_length=ARM_MAX,
        pattern=PRINTABLE,
        description="the physical arm measured (its serial number), for the fleet view",
    )
    target_accuracy_mm: Real | None = Field(
        None,
        gt=0.0,
        le=100.0,
        description=(
            "an adaptive campaign: a D-optimal seed set, then batches of the poses (chosen among "
            "`choose_from` candidates, default 400) that most reduce the predicted held-out "
            "error over the working volume, until that prediction (checked by leave-one-pose-"
            "out) reaches this RMS, the floor, or `poses` poses; each step is kept in the "
            "campaign's settings (`adaptive_steps`) and sent as a `campaign.adaptive` event"
        ),
    )


Coordinate = Field(ge=-COORD_MAX_MM, le=COORD_MAX_MM)


class PointIn(BaseModel):
    """A test point: where the model's first SMR must go, in the cell (tracker) frame, mm."""

    model_config = REQUEST
    point: str = Field(min_length=1, max_length=64, pattern=PRINTABLE)
    x_mm: Real = Coordinate
    y_mm: Real = Coordinate
    z_mm: Real = Coordinate


class VerifyCreate(BaseModel):
    """An ISO 9283 verification run of a job's model on the cell its campaign was measured on:
    each test point visited from several directions, several cycles, with the nominal joints and
    then with the compensated ones."""

    model_config = REQUEST
    name: str = Field("verify", min_length=1, max_length=100, pattern=PRINTABLE)
    cycles: Integer = Field(3, ge=1, le=30)
    directions: Integer = Field(3, ge=1, le=len(DIRECTIONS))
    side_mm: Real = Field(CUBE_SIDE_MM, gt=0, le=5000, description="the ISO cube's side")
    points: list[PointIn] | None = Field(
        None, min_length=1, max_length=20, description="test points (default: the ISO cube's five)"
    )
    pause_s: Real = Field(10.0, ge=0.0, le=600.0)
    start: Flag = Field(True, description="start the run at once (else POST .../start)")


class RunPublic(BaseModel):
    """What this service's acquisition worker did with the campaign since the server started
    (detail only: the campaign's state is `status`)."""

    active: bool = Field(description="queued or running on this service's worker")
    detail: str | None = None
    summary: dict | None = None


ACTIONS_FIELD = Field(
    description="the actions its state allows that this service can carry "
    "out now (start, pause, resume, abort, estop, reset)"
)


class CampaignPublic(BaseModel):
    id: int
    name: str
    kind: Literal["measurement", "verification"] = Field(
        description="a verification run has figures and a certificate"
    )
    created_at: dt.datetime
    status: State = Field(description="the engine's life-cycle state")
    actions: list[Action] = ACTIONS_FIELD
    simulated: bool
    notes: str
    arm: str | None = Field(None, description="the physical arm measured (its serial), if named")
    poses_total: int
    poses_done: int
    run: RunPublic | None = None


class CampaignDetail(CampaignPublic):
    settings: dict


class ActionPublic(CampaignPublic):
    """The campaign after a request: its state before (`was`) and now, what it allows now."""

    was: State
    note: str


class EstopPublic(BaseModel):
    campaign_id: int | None
    status: State | None = None
    was: State | None = None
    confirmed: bool | None = Field(
        None,
        description="the controller confirmed the stop (null: "
        "no run of this service was moving the arm)",
    )
    actions: list[Action] = ACTIONS_FIELD
    note: str


class ReadingPublic(BaseModel):
    pose: str
    pose_index: int
    target: str
    status: str
    xyz: tuple[float, float, float] | None
    std: tuple[float, float, float] | None
    samples: int | None
    time_s: float | None
    temp_c: float | None
    detail: str


class JobCreate(BaseModel):
    model_config = REQUEST
    campaign_id: Integer = Field(ge=1, le=MAX_ID)
    kind: Literal["calibration", "diagnosis"] = "calibration"
    method: str = Field(
        "minimax",
        max_length=64,
        # documented as a pattern, checked by _known_method: a misspelt one gets a suggestion
        json_schema_extra={"pattern": METHOD},
        description="minimax, ls-sum, ls-single[:T], ls-pose, nominal (calibration only)",
    )
    holdout_campaign_id: Annotated[int, Field(ge=1, le=MAX_ID), Whole] | None = Field(
        None,
        description="a calibration's held-out campaign: a done campaign of the same cell it is "
        "not fitted on; the model's error on it is the validation figure, and its poses are the "
        "held-out ones of the recording",
    )
    tolerance_mm: Tolerance | None = Field(
        None,
        description="the accuracy the application needs (mm), over the cell's `tolerance_mm`: "
        "a model whose held-out error exceeds it is not deployable; null: the cell's",
    )

    @field_validator("method")
    @classmethod
    def _known_method(cls, method: str) -> str:
        if re.fullmatch(METHOD, method):
            return method
        name = method.partition(":")[0]
        close = difflib.get_close_matches(name, METHOD_NAMES, n=1)
        raise ValueError(
            f"unknown method {name!r}"
            + (f"; did you mean {close[0]!r}?" if close else "")
            + f" (one of {', '.join(METHOD_NAMES)}; ls-single:TARGET)"
        )


class JobPublic(BaseModel):
    id: int
    kind: Literal["calibration", "diagnosis", "planning"]
    campaign_id: int | None = Field(description="a planning job's: none until it planned one")
    method: str
    state: Literal["queued", "running", "done", "failed"]
    reason: str | None
    progress: float
    created_at: dt.datetime
    started_at: dt.datetime | None
    finished_at: dt.datetime | None
    model_url: str | None = None
    recording_url: str | None = None
    report_url: str | None = None
    figures_url: str | None = None
    campaign_url: str | None = None
    parameters_url: str | None = None
    validation: Validation | None = Field(
        None, description="a done calibration's: is its model deployable, and why not"
    )
    holdout_campaign_id: int | None = Field(None, description="a calibration's held-out campaign")
    tolerance_mm: float | None = Field(
        None, description="the tolerance asked for with the job (null: the cell's is used)"
    )
    holdout: HeldOut | None = Field(
        None, description="a done calibration's errors on its held-out campaign"
    )


class FigurePublic(BaseModel):
    name: str
    url: str
