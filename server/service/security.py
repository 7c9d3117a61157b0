"""The API's bearer token: made at first start, shown once, kept only as its sha256."""

from __future__ import annotations

import hashlib
import hmac
import ipaddress
import os
import secrets
from pathlib import Path
from typing import Annotated

from fastapi import Depends, HTTPException, Request
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer

# 32 random bytes: 256 bits, far beyond guessing, which is why a plain sha256 suffices (a slow
# password hash only helps against low-entropy secrets that a dictionary can enumerate).
TOKEN_BYTES = 32

_bearer = HTTPBearer(
    auto_error=False, description="The token `robocal serve` printed at first start"
)


def token_digest(token: str) -> str:
    """The hex sha256 of a token, as stored."""
    return hashlib.sha256(token.encode()).hexdigest()


def ensure_token(path: Path) -> str | None:
    """Create the token file if there is none; the new token (to show once), else None."""
    path = Path(path)
    if path.exists():
        return None
    path.parent.mkdir(parents=True, exist_ok=True)
    token = secrets.token_urlsafe(TOKEN_BYTES)
    # O_EXCL: two servers starting together cannot both think they created it.
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    with os.fdopen(fd, "w") as f:
        f.write(token_digest(token) + "\n")
    return token


def reset_token(path: Path) -> str:
    """Replace the token (the old one stops working); the new one."""
    Path(path).unlink(missing_ok=True)
    token = ensure_token(path)
    assert token is not None
    return token


def stored_digest(path: Path) -> str:
    """The digest on file; refusing every request (not none) if the file is gone."""
    try:
        return Path(path).read_text().strip()
    except FileNotFoundError:
        return ""


def require_token(
    request: Request, credentials: Annotated[HTTPAuthorizationCredentials | None, Depends(_bearer)]
) -> None:
    """Refuse (401) a request without the service's bearer token."""
    if credentials is None or credentials.scheme.lower() != "bearer":
        raise _unauthorized(
            "this request changes state or moves the robot: it needs "
            "'Authorization: Bearer <token>'"
        )
    # Read each time so deleting or rotating the file takes effect without a restart.
    expected = stored_digest(request.app.state.settings.token_file)
    if not expected or not hmac.compare_digest(token_digest(credentials.credentials), expected):
        raise _unauthorized("the bearer token is not this service's")


def reads_open(settings) -> bool:
    """Whether reads go without the token: asked for, and only on a loopback host."""
    return bool(settings.open_reads) and is_loopback(settings.host)


def is_loopback(host: str) -> bool:
    """Whether the service listens only on this machine (127.0.0.0/8, ::1, localhost)."""
    if host.strip().lower() == "localhost":
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


async def require_reader(
    request: Request, credentials: Annotated[HTTPAuthorizationCredentials | None, Depends(_bearer)]
) -> None:
    """Refuse (401) a read without the token, unless reads are open (see reads_open); async, so
    the e-stop routes it also guards never wait for a thread of the server's pool."""
    if reads_open(request.app.state.settings):
        return
    if credentials is None or credentials.scheme.lower() != "bearer":
        raise _unauthorized(
            "reading the cell's data needs 'Authorization: Bearer <token>' "
            "(the token `robocal serve` printed at first start)"
        )
    require_token(request, credentials)


def _unauthorized(detail: str) -> HTTPException:
    return HTTPException(401, detail, headers={"WWW-Authenticate": "Bearer"})


TokenDep = Depends(require_token)
ReaderDep = Depends(require_reader)
