"""The HTTP API: one router per resource, mounted under /api by server.app.create_app."""

from . import campaigns, cells, jobs, measurements, models

ROUTERS = (cells.router, campaigns.router, measurements.router, jobs.router, models.router)

__all__ = ["ROUTERS"]
