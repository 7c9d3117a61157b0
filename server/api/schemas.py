"""Request and response bodies, one family per resource (Create / Public)."""

from __future__ import annotations

import datetime as dt
from typing import Literal

from pydantic import BaseModel, Field, model_validator

# Ids are SQLite rowids.
MAX_ID = 2**63 - 1
# A name or label: printable, no control characters (NUL, newline, escape, DEL, U+2028/9), so
# that it cannot break a CSV row, a log line or a terminal.
_CTRL = r"\x00-\x1f\x7f-\x9f\u2028\u2029"
PRINTABLE = rf"^[^{_CTRL}]*[^\s{_CTRL}][^{_CTRL}]*$"  # and not blank
# Planning with a D-optimal choice costs about poses x candidates; beyond this product it takes
# seconds, and it runs inside the request (measured: 200 of 1,000 in ~3 s).
CHOICE_WORK_MAX = 200_000
METHOD = r"^(minimax|ls-sum|ls-pose|nominal|ls-single(:[A-Za-z][A-Za-z0-9_]{0,15})?)$"


class CellPublic(BaseModel):
    id: str
    simulated: bool = Field(description="false when the cell has real `devices`")
    cell: dict


class CampaignCreate(BaseModel):
    """A campaign to plan (as `robocal acquire` plans it), on the cell's real devices if it has
    `devices`, else on the simulated ones."""

    name: str | None = Field(None, min_length=1, max_length=200, pattern=PRINTABLE)
    cell_id: str = Field("default", max_length=64)
    poses: int = Field(20, ge=3, le=5000)
    seed: int = Field(0, ge=0, le=2**32 - 1)
    settle: Literal["fixed", "adaptive"] = "fixed"
    pause_s: float = Field(10.0, ge=0.0, le=600.0)
    order: bool = False
    choose_from: int = Field(0, ge=0, le=1000, description=(
        "choose `poses` of this many candidates by D-optimality (0: no choice); "
        f"poses x choose_from at most {CHOICE_WORK_MAX}"))
    beam_break_rate: float = Field(0.0, ge=0.0, lt=1.0, description="simulated cell only")
    samples: int = Field(1000, ge=1, le=100_000)

    @model_validator(mode="after")
    def _bounded_choice(self):
        if self.choose_from and self.poses * self.choose_from > CHOICE_WORK_MAX:
            raise ValueError(f"choosing {self.poses} poses of {self.choose_from} candidates is "
                             f"too long a plan for a request: poses x choose_from must be at "
                             f"most {CHOICE_WORK_MAX}")
        return self


class RunPublic(BaseModel):
    """The acquisition worker's view of the campaign since the server started."""

    state: Literal["running", "finished", "failed", "stopped"]
    stop_requested: str | None = None
    detail: str | None = None
    summary: dict | None = None


class CampaignPublic(BaseModel):
    id: int
    name: str
    created_at: dt.datetime
    status: str
    simulated: bool
    notes: str
    poses_total: int
    poses_done: int
    run: RunPublic | None = None


class CampaignDetail(CampaignPublic):
    settings: dict


class StopPublic(BaseModel):
    id: int
    status: str
    was: str
    note: str


class EstopPublic(BaseModel):
    campaign_id: int | None
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
    campaign_id: int = Field(ge=1, le=MAX_ID)
    kind: Literal["calibration", "diagnosis"] = "calibration"
    method: str = Field("minimax", pattern=METHOD, description="minimax, ls-sum, ls-single[:T], ls-pose, nominal "
                        "(calibration only)")


class JobPublic(BaseModel):
    id: int
    kind: Literal["calibration", "diagnosis"]
    campaign_id: int
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


class FigurePublic(BaseModel):
    name: str
    url: str
