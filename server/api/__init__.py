"""The HTTP API: one router per resource, mounted under /api by server.service.app.create_app."""

from . import campaigns, cells, charts, checks, events, fleet, health, jobs, measurements, models

# Every route of these needs the token (reads too, unless reads are open on loopback).
ROUTERS = (
    cells.router,
    campaigns.router,
    campaigns.estop_router,
    measurements.router,
    jobs.router,
    models.router,
    checks.router,
    events.router,
    charts.router,
    checks.charts_router,
    fleet.router,
)
# Open to anyone: nothing in them says anything about the cell.
OPEN_ROUTERS = (health.router,)

__all__ = ["OPEN_ROUTERS", "ROUTERS"]
