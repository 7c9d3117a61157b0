"""Figures of results: a job's charts and their cache, the diagnosis's effect plots."""
