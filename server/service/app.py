"""The web service: `create_app(settings)` builds it, `serve(settings)` runs it with uvicorn."""

from __future__ import annotations

import errno
import signal
import socket
import sys
from contextlib import asynccontextmanager

import uvicorn
from fastapi import Depends, FastAPI
from fastapi.middleware.cors import CORSMiddleware
from fastapi.routing import APIRoute

from robocal.server import store
from robocal.server.api import OPEN_ROUTERS, ROUTERS, bodies, problems
from robocal.server.api.deps import TOKEN_CHECKS
from robocal.server.api.problems import Responses
from robocal.server.checks import service as check_service
from robocal.server.service.acquisitions import Acquisitions
from robocal.server.service.api_docs import mount_docs
from robocal.server.service.events import Events
from robocal.server.service.job_queue import Jobs
from robocal.server.service.security import ensure_token, require_reader
from robocal.server.service.settings import Settings
from robocal.server.service.viewer import mount_viewer
from robocal.server.service.web import mount_web

API_PREFIX = "/api"
SWITCH_INTERVAL_S = 0.0005
MUTATING = {"POST", "PUT", "PATCH", "DELETE"}


def create_app(settings: Settings | None = None) -> FastAPI:
    """The FastAPI application for these settings (the store opens when it starts)."""
    settings = settings or Settings()

    @asynccontextmanager
    async def lifespan(app: FastAPI):
        # Shown by Server.startup once the service listens (the file keeps just its sha256);
        # serve() deletes it again if the service never got that far, so none is lost unseen.
        app.state.new_token = ensure_token(settings.token_file)
        reports_dir = settings.data_dir / "reports"
        for d in (settings.models_dir, settings.recordings_dir, settings.cells_dir, reports_dir):
            d.mkdir(parents=True, exist_ok=True)
        db = store.open_database(settings.database)
        app.state.db = db
        app.state.events = events = Events()
        # Jobs() fails the jobs a previous process left queued or running.
        app.state.jobs = Jobs(
            db,
            settings.models_dir,
            settings.job_workers,
            recordings_dir=settings.recordings_dir,
            reports_dir=reports_dir,
            events=events,
            viewer_url=settings.rerun_viewer_url,
            timeout_s=settings.job_timeout_s,
            call_timeout_s=settings.call_timeout_s,
            call_workers=settings.call_workers,
        )
        app.state.acquisitions = Acquisitions(
            db, events, on_done=lambda cid: check_service.judge_done(db, cid)
        )
        try:
            yield
        finally:
            events.close()
            app.state.acquisitions.shutdown()
            app.state.jobs.shutdown()
            db.close()

    app = FastAPI(
        title="robocal",
        summary="Robot calibration workstation",
        version="0.1.0",
        lifespan=lifespan,
        docs_url=None,  # mount_docs serves it without a CDN
        redoc_url=None,  # ReDoc would load from a CDN, blank offline
    )
    app.state.settings = settings
    problems.install(app)
    bodies.install(app, settings.max_upload_bytes)
    if settings.cors_origins:  # closed unless origins are listed
        app.add_middleware(
            CORSMiddleware,
            allow_origins=settings.cors_origins,
            allow_methods=["*"],
            allow_headers=["Authorization", "Content-Type"],
        )
    for router in ROUTERS:
        document_errors(router, settings.max_upload_bytes)
        # Reads need the token too (unless reads are open on loopback); writes list their own.
        app.include_router(router, prefix=API_PREFIX, dependencies=[Depends(require_reader)])
    for router in OPEN_ROUTERS:
        app.include_router(router, prefix=API_PREFIX)
    check_authorized(app)
    mount_docs(app)
    mount_viewer(app, settings.viewer_dir)
    mount_web(app)  # last: a mount at / hides any route added after it
    return app


def document_errors(router, max_upload_bytes: int) -> None:
    """Add to each route's OpenAPI the problem-details answers it can give: 401 (the token),
    404/409/422 (the store and validation), 413 on writes (with the route's limit), 502 where a
    device is driven. A route's own `responses=` entries win."""
    for route in router.routes:
        if not isinstance(route, APIRoute):
            continue
        extra: Responses = {**problems.UNAUTHORIZED, **problems.READ_ERRORS}
        if (route.methods or set()) & MUTATING:
            extra.update(problems.WRITE_ERRORS)
            if route.path.startswith(("/campaigns", "/estop")):
                extra.update(problems.DEVICE_ERRORS)
        route.responses = {**extra, **route.responses}
        bodies.document_limit(route, API_PREFIX + route.path, max_upload_bytes)


def unguarded_routes(app: FastAPI) -> list[str]:
    """Routes that do not require the token (should be none): every mutating route needs
    require_token, every read require_reader, except the open ones (GET /api/health)."""
    open_paths = {
        API_PREFIX + r.path
        for router in OPEN_ROUTERS
        for r in router.routes
        if isinstance(r, APIRoute)
    }
    bad = []
    for route in _api_routes(app.routes):
        calls = {d.call for d in _flat(route.dependant)}
        if route.methods & MUTATING:
            guarded = bool(calls & set(TOKEN_CHECKS))
        else:
            guarded = route.path in open_paths or bool(calls & {*TOKEN_CHECKS, require_reader})
        if not guarded:
            bad.append(f"{','.join(sorted(route.methods))} {route.path}")
    return bad


def _api_routes(routes):
    for route in routes:
        if isinstance(route, APIRoute):
            yield route
        # FastAPI >= 0.16x keeps included routers as lazy wrappers around the original router;
        # their effective routes carry the dependencies and prefix given at include_router.
        candidates = getattr(route, "effective_candidates", None)
        if candidates is not None:
            for c in candidates():
                if hasattr(c, "effective_candidates"):
                    yield from _api_routes([c])
                elif hasattr(c, "dependant"):
                    yield c


def check_authorized(app: FastAPI) -> None:
    """Refuse to build an app where a route forgot the token: fail closed."""
    bad = unguarded_routes(app)
    if bad:
        raise RuntimeError(f"routes without require_token: {', '.join(bad)}")


def _flat(dependant):
    for d in dependant.dependencies:
        yield d
        yield from _flat(d)


# After SIGTERM or Ctrl-C (the arm already stopped) requests in flight get this long to finish.
GRACE_S = 5  # uvicorn takes whole seconds


class Server(uvicorn.Server):
    """uvicorn's server, but SIGTERM or Ctrl-C stops the arm first: uvicorn runs the app's
    shutdown only after draining the requests in flight, while the arm would keep moving."""

    def __init__(self, config: uvicorn.Config, app: FastAPI):
        super().__init__(config)
        self.app = app

    async def startup(self, sockets=None) -> None:
        await super().startup(sockets)
        settings = self.app.state.settings
        if not self.started:
            return
        token = getattr(self.app.state, "new_token", None)
        if token is not None:
            print(f"robocal: API token (shown once, keep it): {token}", file=sys.stderr, flush=True)
            self.app.state.new_token = None
        else:
            print(
                f"robocal: API token: the one shown at its first start (kept only as a hash in "
                f"{settings.token_file}); lost it? `robocal token reset"
                f"{_data_dir_option(settings)}` prints a new one",
                file=sys.stderr,
                flush=True,
            )
        if sockets is not None:  # uvicorn says where it runs only for sockets it bound itself
            self._log_started_message(sockets)

    def handle_exit(self, sig, frame) -> None:
        acquisitions = getattr(self.app.state, "acquisitions", None)
        if acquisitions is not None and not self.should_exit:
            outcome = acquisitions.estop_all()  # waits at most the controller's confirmation
            if outcome is not None and outcome.campaign_id is not None:
                print(
                    f"robocal: {signal.Signals(sig).name}: campaign {outcome.campaign_id} "
                    f"e-stopped (confirmed: {outcome.confirmed})",
                    file=sys.stderr,
                    flush=True,
                )
        super().handle_exit(sig, frame)


def serve(settings: Settings | None = None) -> None:
    """Run the service with uvicorn on settings.host:port (127.0.0.1 unless told otherwise)."""
    settings = settings or Settings()
    # A thread waiting for the GIL gets it after at most this long: the e-stop's threads must
    # not queue behind request threads for the default 5 ms per turn.
    sys.setswitchinterval(SWITCH_INTERVAL_S)
    sock = listening_socket(settings.host, settings.port)
    app = create_app(settings)
    try:
        Server(
            uvicorn.Config(
                app,
                host=settings.host,
                port=settings.port,
                log_level="info",
                timeout_graceful_shutdown=GRACE_S,
            ),
            app,
        ).run(sockets=[sock])
    finally:
        sock.close()
        if getattr(app.state, "new_token", None) is not None:
            # Made but never shown (the service failed to start): the next start makes another.
            settings.token_file.unlink(missing_ok=True)


class CannotListen(OSError):
    """The service's address is taken or not this machine's; the message says which."""


def listening_socket(host: str, port: int) -> socket.socket:
    """A socket bound to host:port, before anything else starts (the token is not made, nor
    shown, for a service that cannot listen)."""
    try:
        family, kind, proto, _, addr = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM)[0]
    except socket.gaierror as e:
        raise CannotListen(f"cannot listen on {host}:{port}: {e.strerror}") from None
    sock = socket.socket(family, kind, proto)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # as uvicorn does
    try:
        sock.bind(addr)
    except OSError as e:
        sock.close()
        hint = (
            ": is another robocal serve running? stop it, or choose another --port"
            if e.errno == errno.EADDRINUSE
            else ""
        )
        raise CannotListen(f"cannot listen on {host}:{port}: {e.strerror}{hint}") from None
    return sock


def _data_dir_option(settings: Settings) -> str:
    """The `--data-dir` a command needs to find this service's data, if not the default."""
    default = Settings.model_fields["data_dir"].default
    return "" if settings.data_dir == default else f" --data-dir {settings.data_dir}"
