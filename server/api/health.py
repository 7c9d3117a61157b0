"""Health: GET /api/health answers without the token, for a load balancer or a watchdog."""

from __future__ import annotations

from fastapi import APIRouter
from pydantic import BaseModel

router = APIRouter(tags=["health"])


class HealthPublic(BaseModel):
    status: str


@router.get("/health")
def health() -> HealthPublic:
    """The service is up and answering (no token needed; says nothing about the cell)."""
    return HealthPublic(status="ok")
