"""The HTTP API: one router per resource, mounted under /api by server.app.create_app."""

from . import campaigns, cells, charts, events, jobs, measurements, models

ROUTERS = (cells.router, campaigns.router, campaigns.estop_router, measurements.router,
           jobs.router, models.router, events.router, charts.router)

__all__ = ["ROUTERS"]
