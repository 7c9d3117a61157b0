"""Rerun's web viewer at /viewer/: its code from the installed rerun-sdk, served by the service
itself so the page shows a calibration's recording in 3-D without the internet.

The code is public like the page (web/viewer.html hosts it); a recording is not: the page fetches
it from GET /api/jobs/{id}/recording with the token and hands the bytes to the viewer.
"""

from __future__ import annotations

from pathlib import Path

from fastapi import FastAPI
from starlette.concurrency import run_in_threadpool
from starlette.exceptions import HTTPException
from starlette.requests import Request
from starlette.responses import FileResponse, Response

from robocal.server.service.viewer_assets import ASSETS, ViewerUnavailable, viewer_dir

VIEWER_URL = "/viewer"
MEDIA = {".js": "text/javascript", ".wasm": "application/wasm"}


def mount_viewer(app: FastAPI, cache_root: Path) -> None:
    """Serve ASSETS at /viewer/<name>, taken from rerun-sdk into cache_root on first request.

    Call it before mount_web: the page's mount at / would answer /viewer/* itself.
    """

    async def asset(request: Request) -> Response:
        name = request.path_params["name"]
        if name not in ASSETS:
            raise HTTPException(404, f"no viewer file {name!r}; there are {', '.join(ASSETS)}")
        try:
            folder = await run_in_threadpool(viewer_dir, cache_root)
        except ViewerUnavailable as e:
            raise HTTPException(503, f"the 3-D viewer is not available here: {e}") from e
        path = folder / name
        # no-cache: revalidated each load (304 by its ETag), so a new rerun-sdk is picked up
        return FileResponse(
            path, media_type=MEDIA[path.suffix], headers={"Cache-Control": "no-cache"}
        )

    app.add_route(f"{VIEWER_URL}/{{name}}", asset, methods=["GET", "HEAD"], include_in_schema=False)


__all__ = ["VIEWER_URL", "mount_viewer"]
