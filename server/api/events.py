"""Live events: GET /api/events streams campaign and job progress as server-sent events."""

from __future__ import annotations

import json

from fastapi import APIRouter, Request
from sse_starlette import EventSourceResponse, ServerSentEvent

from .deps import EventsDep

router = APIRouter(tags=["events"])
# Comments at this interval keep proxies and browsers from dropping a quiet stream.
PING_S = 15


@router.get(
    "/events",
    response_class=EventSourceResponse,
    responses={
        200: {
            "content": {
                "text/event-stream": {
                    "schema": {"type": "string", "description": "server-sent events, endless"}
                }
            }
        }
    },
)
async def events(request: Request, bus: EventsDep) -> EventSourceResponse:
    """Server-sent events: `event:` is the type (campaign.state, campaign.pose, campaign.run,
    job), `data:` its JSON object; events from before the connection are not replayed."""
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
