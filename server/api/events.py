"""Live events: GET /api/events streams campaign and job progress as server-sent events."""

from __future__ import annotations

import datetime as dt
import json
from typing import Any, Literal, get_args

from fastapi import APIRouter, Request
from pydantic import BaseModel, Field
from sse_starlette import EventSourceResponse, ServerSentEvent

from .deps import EventsDep
from .schemas import State

router = APIRouter(tags=["events"])
# Comments at this interval keep proxies and browsers from dropping a quiet stream.
PING_S = 15


class CampaignStateEvent(BaseModel):
    """A campaign's life-cycle state changed."""

    type: Literal["campaign.state"]
    campaign_id: int
    state: State
    was: State
    time: dt.datetime = Field(description="when the service published it (UTC)")


class CampaignPoseEvent(BaseModel):
    """A pose of a running campaign was measured (or skipped)."""

    type: Literal["campaign.pose"]
    campaign_id: int
    pose_index: int
    pose_state: str = Field(description="the pose's outcome (measured, unreachable...)")
    poses_done: int
    poses_total: int
    readings: int = Field(description="readings taken so far in this run")
    missing: int = Field(description="targets missing so far in this run (beam breaks)")
    state: State
    time: dt.datetime


class CampaignAdaptiveEvent(BaseModel):
    """An adaptive campaign refitted its readings: the accuracy it predicts, and whether it
    stops (the step as the campaign's settings keep it, `adaptive_steps`)."""

    type: Literal["campaign.adaptive"]
    campaign_id: int
    poses: int = Field(description="the poses the step fitted")
    predicted_mm: float = Field(description="predicted held-out RMS over the working volume")
    floor_mm: float = Field(description="what it tends to with endless poses")
    parameters_mm: float = Field(description="the parameters' part of it")
    holdout_mm: float | None = Field(description="the fit's own leave-one-pose-out RMS")
    expected_holdout_mm: float = Field(description="what the noise alone would give that")
    kappa: float = Field(description="the data's check on the prediction's parameters' part (>= 1)")
    stop: bool
    reason: str = Field(description="target, floor or maximum when it stops, else empty")
    message: str
    campaign_s: float | None = Field(description="the campaign clock at the step")
    effects: list[str] = Field(
        default_factory=list, description="the effects the step's fit included (their labels)"
    )
    named: list[str] | None = Field(
        None, description="what the step's diagnosis named (null: no diagnosis at this step)"
    )
    extensions: list[dict] = Field(
        default_factory=list, description="the included effects, fitted, as model.json has them"
    )
    time: dt.datetime


class CampaignRunEvent(BaseModel):
    """This service's run of a campaign ended: the campaign's state then, and why."""

    type: Literal["campaign.run"]
    campaign_id: int
    state: State | None
    detail: str | None
    time: dt.datetime


class JobEvent(BaseModel):
    """A job was queued, progressed or ended."""

    type: Literal["job"]
    job_id: int
    kind: Literal["calibration", "diagnosis", "planning"]
    campaign_id: int | None
    state: Literal["queued", "running", "done", "failed"]
    progress: float
    reason: str | None
    time: dt.datetime


EVENTS = (CampaignStateEvent, CampaignPoseEvent, CampaignAdaptiveEvent, CampaignRunEvent, JobEvent)


def event_item_schema() -> dict[str, Any]:
    """One server-sent event as OpenAPI's `itemSchema` of text/event-stream says it (as FastAPI's
    own SSE routes document theirs): `event` its type, `data` its JSON object, `id` its number."""
    return {
        "type": "object",
        "required": ["event", "data", "id"],
        "properties": {
            "event": {
                "type": "string",
                "enum": [get_args(e.model_fields["type"].annotation)[0] for e in EVENTS],
            },
            "id": {"type": "string", "pattern": "^[0-9]+$"},
            "data": {
                "type": "string",
                "contentMediaType": "application/json",
                "contentSchema": {"oneOf": [e.model_json_schema() for e in EVENTS]},
            },
        },
    }


@router.get(
    "/events",
    response_class=EventSourceResponse,
    responses={
        200: {
            "description": "server-sent events, endless; `: ping` comments keep it open",
            "content": {"text/event-stream": {"itemSchema": event_item_schema()}},
        }
    },
)
async def events(request: Request, bus: EventsDep) -> EventSourceResponse:
    """Server-sent events: `event:` is the type (campaign.state, campaign.pose,
    campaign.adaptive, campaign.run, job), `data:` its JSON object; events from before the connection are not replayed."""
    # Subscribed before the response starts, so nothing published after the headers is missed.
    queue = bus.subscribe()

    async def stream():
        try:
            yield ServerSentEvent(comment="robocal events")
            while True:
                item = await queue.get()
                if item is None:  # the service is stopping
                    return
                event_id, event = item
                yield ServerSentEvent(data=json.dumps(event), event=event["type"], id=str(event_id))
        finally:
            bus.unsubscribe(queue)

    return EventSourceResponse(stream(), ping=PING_S)
