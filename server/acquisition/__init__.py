"""Acquisition: `robocal acquire`, the service's runner, campaign planning, the campaigns and cells kept."""
