"""Errors as RFC 9457 problem details (application/problem+json)."""

from __future__ import annotations

from http import HTTPStatus
from typing import Any

from fastapi import FastAPI, Request
from fastapi.encoders import jsonable_encoder
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from pydantic import BaseModel, ConfigDict
from starlette.exceptions import HTTPException as StarletteHTTPException

from robocal.drivers.lifecycle import StateError
from robocal.server.formats.errors import InputError
from robocal.server.service.acquisitions import ControllerUnreachable
from robocal.server.store import Conflict, DatabaseGone, NotFound, StoreError, StoreUnavailable
from robocal.server.store.errors import RETRY_AFTER_S, unavailable

MEDIA_TYPE = "application/problem+json"


class Problem(BaseModel):
    """An RFC 9457 problem-details body; some refusals add members (errors, file, line, state)."""

    model_config = ConfigDict(extra="allow")
    type: str = "about:blank"
    title: str
    status: int
    detail: str
    instance: str


def problem_response(description: str) -> dict:
    """An OpenAPI `responses` entry for a problem-details answer."""
    return {
        "description": description,
        "content": {MEDIA_TYPE: {"schema": Problem.model_json_schema()}},
    }


# What every route may answer besides its success (server.service.app adds them to each route's
# OpenAPI): statuses by which routes can give them.
# FastAPI's `responses=`: the OpenAPI answers a route documents beside its own, by status code
Responses = dict[int | str, dict[str, Any]]
UNAUTHORIZED: Responses = {401: problem_response("no or wrong bearer token")}
READ_ERRORS: Responses = {
    404: problem_response("no such resource"),
    409: problem_response("the resource is not in a state that allows this"),
    422: problem_response(
        "the request (or an uploaded file) is invalid; the "
        "detail names the field, or the file's line and column"
    ),
    503: problem_response(
        "the database could not read or write (a full or read-only disk, an I/O error): the "
        "service's fault, nothing of the request was stored; `reason` says what failed, "
        "Retry-After when to ask again"
    ),
}
WRITE_ERRORS: Responses = {
    400: problem_response("the body is not valid JSON"),
    # server.service.app replaces it with the route's own limit (api.bodies)
    413: problem_response("the request body is larger than the route takes"),
}
DEVICE_ERRORS: Responses = {
    502: problem_response(
        "a device (controller, tracker) did not answer as it must; the arm may still move"
    )
}


def problem(request: Request, status: int, detail: str, headers=None, **extra) -> JSONResponse:
    """A problem-details response."""
    body = {
        "type": "about:blank",
        "title": HTTPStatus(status).phrase,
        "status": status,
        "detail": detail,
        "instance": request.url.path,
        **extra,
    }
    return JSONResponse(
        jsonable_encoder(body), status_code=status, headers=headers, media_type=MEDIA_TYPE
    )


def _schema_detail(errors: list[dict]) -> str:
    """One line naming the first field refused (without its `body` or `query` prefix) and why."""
    said = "the request does not match the schema"
    if not errors:
        return said
    loc = [str(part) for part in errors[0].get("loc", ())]
    if len(loc) > 1 and loc[0] in ("body", "query", "path", "header"):
        loc = loc[1:]
    why = " ".join(str(errors[0].get("msg", "")).split())
    more = f" (and {len(errors) - 1} more)" if len(errors) > 1 else ""
    return f"{said}: {'.'.join(loc)}: {why}{more}"


def install(app: FastAPI) -> None:
    """Register the handlers that turn every refusal into a problem-details body."""

    @app.exception_handler(StarletteHTTPException)
    async def http_error(request: Request, exc: StarletteHTTPException):
        return problem(request, exc.status_code, str(exc.detail), headers=exc.headers)

    @app.exception_handler(RequestValidationError)
    async def validation_error(request: Request, exc: RequestValidationError):
        errors = [{k: e[k] for k in ("loc", "msg", "type") if k in e} for e in exc.errors()]
        return problem(request, 422, _schema_detail(errors), errors=errors)

    @app.exception_handler(InputError)
    async def input_error(request: Request, exc: InputError):
        # The uploaded file's own line and column, so the user can fix it in an editor.
        return problem(request, 422, str(exc), file=exc.path, line=exc.line, column=exc.column)

    @app.exception_handler(StateError)
    async def state_error(request: Request, exc: StateError):
        # The campaign's state does not allow the action: say the state and what it allows.
        return problem(request, 409, str(exc), state=exc.state, allowed_actions=exc.allowed)

    @app.exception_handler(StoreUnavailable)
    async def store_unavailable(request: Request, exc: StoreUnavailable):
        # The disk's fault, not the request's: nothing was stored, the same request may succeed
        # once the disk is fixed.
        return problem(
            request,
            503,
            str(exc),
            headers={"Retry-After": str(RETRY_AFTER_S)},
            reason=exc.reason,
        )

    @app.exception_handler(OSError)
    async def os_error(request: Request, exc: OSError):
        # A file of the data dir (a cell, an upload) on a full or read-only disk: the same 503.
        fault = unavailable(exc)
        if fault is None:
            raise exc  # any other OSError is a bug: the server's own 500
        return await store_unavailable(request, fault)

    # Store and device errors map to one status each; the store and the solver front ends raise
    # ValueError for bad arguments only. A 502 means the arm may still move: said loudly.
    statuses = (
        (NotFound, 404),
        (Conflict, 409),
        (DatabaseGone, 503),  # the service's, not the user's: restart it on its file
        (StoreError, 422),
        (ControllerUnreachable, 502),
        (ValueError, 422),
    )
    for exc_type, status in statuses:

        async def handler(request: Request, exc: Exception, status: int = status):
            return problem(request, status, str(exc))

        app.add_exception_handler(exc_type, handler)
