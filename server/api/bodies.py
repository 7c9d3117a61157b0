"""Request bodies: the largest each route takes, refused (413) before it is read, and JSON
requests validated off the event loop, so that no body holds up the e-stop.

Why a bound and not only a thread: json and pydantic parse in C and hold the GIL for the whole
call (30 MB: over a second, every thread of the service waiting), so what keeps the loop and the
stop threads free is that no route parses more than a few milliseconds' worth in the service.
Only the file uploads parsed in a worker process (meas.csv, targets.csv) take max_upload_bytes."""

from __future__ import annotations

from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from typing import Any, TypeVar

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.routing import APIRoute
from pydantic import BaseModel, ValidationError
from pydantic.json_schema import models_json_schema
from starlette.concurrency import run_in_threadpool
from starlette.exceptions import HTTPException as StarletteHTTPException
from starlette.routing import compile_path

from .problems import problem, problem_response

# A JSON request (a campaign, a job, a verification run): a few hundred bytes; parsed in at
# most a few milliseconds even on a loaded machine.
JSON_BODY_BYTES = 64 * 1024
# A cell.json: a robot, at most a few SMRs, a base, its devices: a few kilobytes. Its parse
# holds the GIL too, so it is bounded as tightly as a plausible cell allows.
CELL_BODY_BYTES = 256 * 1024
# The routes whose body is a file of measurements or targets, parsed in a worker process: these
# take max_upload_bytes. Paths as served (under /api).
UPLOADS = frozenset(
    {
        ("POST", "/api/measurements/import"),
        ("POST", "/api/models/{job_id}/compensate"),
        ("POST", "/api/models/{job_id}/export"),
        ("POST", "/api/models/{job_id}/checks"),
    }
)
CELLS = frozenset({("POST", "/api/cells")})
# The e-stops read no body: whatever comes with one, the arm is stopped, never refused a 413.
ESTOPS = frozenset({("POST", "/api/estop"), ("POST", "/api/campaigns/{campaign_id}/estop")})


@dataclass(frozen=True)
class RouteLimit:
    """The largest body a route takes, and what the refusal tells the user to do."""

    max_bytes: int
    advice: str

    def detail(self) -> str:
        return f"the request body is larger than {self.max_bytes} bytes; {self.advice}"


def limit_of(method: str, path: str, max_upload_bytes: int) -> RouteLimit | None:
    """The body limit of a route (its path as served, with its {parameters}); None: none."""
    if (method, path) in ESTOPS:
        return None
    if (method, path) in UPLOADS:
        return RouteLimit(
            max_upload_bytes,
            "split the file (setting max_upload_bytes, env ROBOCAL_MAX_UPLOAD_BYTES)",
        )
    if (method, path) in CELLS:
        return RouteLimit(min(CELL_BODY_BYTES, max_upload_bytes), "a cell.json is a few kilobytes")
    return RouteLimit(
        min(JSON_BODY_BYTES, max_upload_bytes), "this route takes a small JSON request"
    )


class RouteLimits:
    """The limits of the routes named here by method and path; any other request takes a
    small JSON body."""

    def __init__(self, max_upload_bytes: int):
        self._named = [
            (method, compile_path(path)[0], limit_of(method, path, max_upload_bytes))
            for method, path in UPLOADS | CELLS | ESTOPS
        ]
        self._small = limit_of("", "", max_upload_bytes)

    def of(self, method: str, path: str) -> RouteLimit | None:
        for m, regex, limit in self._named:
            if m == method and regex.match(path):
                return limit
        return self._small


class BodyLimit:
    """Refuse (413, problem details) a request body over its route's limit: at once when its
    Content-Length says so, else as soon as the streamed bytes pass it, so no body is held in
    memory, or parsed, beyond its route's limit."""

    def __init__(self, app, limits: RouteLimits):
        self.app, self.limits = app, limits

    async def __call__(self, scope, receive, send):
        if scope["type"] != "http":
            return await self.app(scope, receive, send)
        limit = self.limits.of(scope["method"], scope["path"])
        if limit is None:
            return await self.app(scope, receive, send)
        length = dict(scope["headers"]).get(b"content-length", b"")
        if length.isdigit() and int(length) > limit.max_bytes:
            response = problem(Request(scope), 413, limit.detail())
            return await response(scope, receive, send)
        seen = 0

        async def counted():
            nonlocal seen
            message = await receive()
            seen += len(message.get("body", b""))
            if seen > limit.max_bytes:
                # Raised inside the route's body read: the exception handlers answer it.
                raise StarletteHTTPException(413, limit.detail())
            return message

        await self.app(scope, counted, send)


M = TypeVar("M", bound=BaseModel)
# The models read_json reads: put in the OpenAPI's components, as a body parameter's would be.
_BODY_MODELS: list[type[BaseModel]] = []


def _validated(model: type[M], data: bytes) -> M:
    """The body as the model, or the 422 a body parameter gets (locations under `body`)."""
    if not data:
        raise RequestValidationError(
            [{"type": "missing", "loc": ("body",), "msg": "Field required", "input": None}]
        )
    try:
        return model.model_validate_json(data)
    except ValidationError as e:
        raise RequestValidationError(
            [{**err, "loc": ("body", *err["loc"])} for err in e.errors(include_url=False)]
        ) from None


def read_json(model: type[M]) -> Callable[[Request], Awaitable[M]]:
    """A dependency: the request's JSON body as `model`, read on the loop (bounded already by
    BodyLimit), parsed and validated on a worker thread. Its route documents the body with
    `openapi_extra=json_body(model)`."""

    async def read(request: Request) -> M:
        data = await request.body()
        return await run_in_threadpool(_validated, model, data)

    _BODY_MODELS.append(model)
    return read


def json_body(model: type[BaseModel]) -> dict:
    """The `openapi_extra` of a route reading `model` with read_json: its request body as
    FastAPI documents a body parameter."""
    ref = {"$ref": f"#/components/schemas/{model.__name__}"}
    return {"requestBody": {"required": True, "content": {"application/json": {"schema": ref}}}}


def csv_body(description: str) -> dict:
    """The `openapi_extra` of a route reading a CSV file as its body: non-empty text/csv (the
    spec's CSV files begin with a header row, so an empty file is refused)."""
    schema = {"type": "string", "minLength": 1, "description": description}
    return {"requestBody": {"required": True, "content": {"text/csv": {"schema": schema}}}}


def install(app: FastAPI, max_upload_bytes: int) -> None:
    """Bound every route's body, and put the read_json models in the OpenAPI components."""
    app.add_middleware(BodyLimit, limits=RouteLimits(max_upload_bytes))
    generate = app.openapi

    def openapi() -> dict[str, Any]:
        if app.openapi_schema:
            return app.openapi_schema
        schema = generate()
        _, defs = models_json_schema(
            [(m, "validation") for m in _BODY_MODELS], ref_template="#/components/schemas/{model}"
        )
        components = schema.setdefault("components", {}).setdefault("schemas", {})
        for name, model_schema in defs.get("$defs", {}).items():
            components.setdefault(name, model_schema)
        return schema

    app.openapi = openapi  # type: ignore[method-assign]


def document_limit(route: APIRoute, path: str, max_upload_bytes: int) -> None:
    """The route's 413 entry (if it has one) names its own limit (none: no entry); path: as
    served."""
    limits = [limit_of(m, path, max_upload_bytes) for m in route.methods or ()]
    if 413 not in route.responses:
        return
    if not limits or None in limits:  # no limit: no 413
        del route.responses[413]
    else:
        details = sorted({x.detail() for x in limits if x is not None})
        route.responses[413] = problem_response("; ".join(details))
