"""The dependencies routes declare: the store, the settings, the worker tables, the token."""

from __future__ import annotations

from typing import Annotated, Literal

from fastapi import Depends, Path, Query, Request
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer

from robocal.server.service.acquisitions import Acquisitions
from robocal.server.service.events import Events
from robocal.server.service.job_queue import Jobs
from robocal.server.service.security import require_token
from robocal.server.service.settings import Settings
from robocal.server.store import Database
from robocal.server.store.models import STATUSES


def get_db(request: Request) -> Database:
    return request.app.state.db


def get_settings(request: Request) -> Settings:
    return request.app.state.settings


def get_jobs(request: Request) -> Jobs:
    return request.app.state.jobs


def get_acquisitions(request: Request) -> Acquisitions:
    return request.app.state.acquisitions


def get_events(request: Request) -> Events:
    return request.app.state.events


DbDep = Annotated[Database, Depends(get_db)]
SettingsDep = Annotated[Settings, Depends(get_settings)]
JobsDep = Annotated[Jobs, Depends(get_jobs)]
AcquisitionsDep = Annotated[Acquisitions, Depends(get_acquisitions)]
EventsDep = Annotated[Events, Depends(get_events)]


async def require_token_now(
    request: Request,
    credentials: Annotated[
        HTTPAuthorizationCredentials | None, Depends(HTTPBearer(auto_error=False))
    ],
) -> None:
    """require_token on the event loop, for the e-stop routes: a sync dependency would wait for
    a thread of the server's pool, behind every request in it."""
    require_token(request, credentials)


# Every POST / PUT / PATCH / DELETE route lists one of these; create_app refuses to build
# otherwise.
Authorized = Depends(require_token)
AuthorizedNow = Depends(require_token_now)
TOKEN_CHECKS = (require_token, require_token_now)

# Ids are SQLite rowids: 1 .. 2**63 - 1; anything else is a 422, never an overflow in the store.
MAX_ID = 2**63 - 1
CampaignId = Annotated[int, Path(ge=1, le=MAX_ID, description="a campaign's id")]
JobId = Annotated[int, Path(ge=1, le=MAX_ID, description="a job's id")]
CampaignQuery = Annotated[int, Query(ge=1, le=MAX_ID, description="a campaign's id")]
# the store's statuses, listed in the OpenAPI; mypy takes only literals written out in a Literal
CampaignStatus = Literal[STATUSES]  # type: ignore[valid-type]
