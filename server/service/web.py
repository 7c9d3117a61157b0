"""The browser page: `mount_web(app)` serves web/ (index.html, app.js, style.css) at `/`."""

from __future__ import annotations

from pathlib import Path

from fastapi import FastAPI
from fastapi.staticfiles import StaticFiles
from starlette.exceptions import HTTPException
from starlette.routing import Match

WEB_DIR = Path(__file__).resolve().parents[2] / "web"


class _Page(StaticFiles):
    """StaticFiles that leaves /api/* alone: an unknown API route is a 404 problem, not a file."""

    async def get_response(self, path: str, scope):
        if path == "api" or path.startswith("api/"):
            # A route that exists with other methods: 405 naming them (the mount at / matches
            # every path, so the router never gets to say it).
            allowed = _allowed_methods(scope["app"], "/" + path)
            # the file server's path is normalised ("api/fleet/x/.." is "api/fleet"): a method the
            # route takes means the request's own path matched no route
            if allowed and scope["method"] not in allowed:
                raise HTTPException(
                    405,
                    f"/{path} allows {', '.join(allowed)}, not {scope['method']}",
                    headers={"Allow": ", ".join(allowed)},
                )
            # Without this, POST /api/<missing> would answer 405 from the file server.
            raise HTTPException(404, f"no API route {scope['method']} {scope['path']}")
        return await super().get_response(path, scope)


def _allowed_methods(app, path: str) -> list[str]:
    """The methods the app's routes take at this path (none: no such route)."""
    allowed = set()
    for method in ("GET", "POST", "PUT", "PATCH", "DELETE"):
        probe = {"type": "http", "path": path, "root_path": "", "method": method}
        for route in app.router.routes:
            if getattr(route, "path", None) == "" or type(route).__name__ == "Mount":
                continue
            if route.matches(probe)[0] == Match.FULL:
                allowed.add(method)
                break
    if "GET" in allowed:
        allowed.add("HEAD")
    return sorted(allowed)


def mount_web(app: FastAPI) -> None:
    """Serve the page at `/`; call it after the API routers are included, or it shadows them."""
    app.mount("/", _Page(directory=WEB_DIR, html=True), name="web")
