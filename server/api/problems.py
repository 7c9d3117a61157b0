"""Errors as RFC 9457 problem details (application/problem+json)."""

from __future__ import annotations

from http import HTTPStatus

from fastapi import FastAPI, Request
from fastapi.encoders import jsonable_encoder
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from starlette.exceptions import HTTPException as StarletteHTTPException

from drivers.lifecycle import StateError
from server.formats.errors import InputError
from server.acquisitions import ControllerUnreachable
from server.store import Conflict, NotFound, StoreError

MEDIA_TYPE = "application/problem+json"


def problem(request: Request, status: int, detail: str, headers=None, **extra) -> JSONResponse:
    """A problem-details response."""
    body = {"type": "about:blank", "title": HTTPStatus(status).phrase, "status": status,
            "detail": detail, "instance": request.url.path, **extra}
    return JSONResponse(jsonable_encoder(body), status_code=status, headers=headers,
                        media_type=MEDIA_TYPE)


def install(app: FastAPI) -> None:
    """Register the handlers that turn every refusal into a problem-details body."""

    @app.exception_handler(StarletteHTTPException)
    async def http_error(request: Request, exc: StarletteHTTPException):
        return problem(request, exc.status_code, str(exc.detail), headers=exc.headers)

    @app.exception_handler(RequestValidationError)
    async def validation_error(request: Request, exc: RequestValidationError):
        errors = [{k: e[k] for k in ("loc", "msg", "type") if k in e} for e in exc.errors()]
        return problem(request, 422, "the request does not match the schema", errors=errors)

    @app.exception_handler(InputError)
    async def input_error(request: Request, exc: InputError):
        # The uploaded file's own line and column, so the user can fix it in an editor.
        return problem(request, 422, str(exc), file=exc.path, line=exc.line, column=exc.column)

    @app.exception_handler(StateError)
    async def state_error(request: Request, exc: StateError):
        # The campaign's state does not allow the action: say the state and what it allows.
        return problem(request, 409, str(exc), state=exc.state, allowed_actions=exc.allowed)

    # Store and device errors map to one status each; the store and the solver front ends raise
    # ValueError for bad arguments only. A 502 means the arm may still move: said loudly.
    statuses = ((NotFound, 404), (Conflict, 409), (StoreError, 422),
                (ControllerUnreachable, 502), (ValueError, 422))
    for exc_type, status in statuses:
        async def handler(request: Request, exc: Exception, status: int = status):
            return problem(request, status, str(exc))
        app.add_exception_handler(exc_type, handler)
