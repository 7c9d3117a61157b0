"""The browser page: `mount_web(app)` serves web/ (index.html, app.js, style.css) at `/`."""

from __future__ import annotations

from pathlib import Path

from fastapi import FastAPI
from fastapi.staticfiles import StaticFiles
from starlette.exceptions import HTTPException

WEB_DIR = Path(__file__).resolve().parent.parent / "web"


class _Page(StaticFiles):
    """StaticFiles that leaves /api/* alone: an unknown API route is a 404 problem, not a file."""

    async def get_response(self, path: str, scope):
        if path == "api" or path.startswith("api/"):
            # Without this, POST /api/<missing> would answer 405 from the file server.
            raise HTTPException(404, f"no API route {scope['method']} /{path}")
        return await super().get_response(path, scope)


def mount_web(app: FastAPI) -> None:
    """Serve the page at `/`; call it after the API routers are included, or it shadows them."""
    app.mount("/", _Page(directory=WEB_DIR, html=True), name="web")
