"""Fixtures of the store tests: each test its own store, on each backend (file or PostgreSQL)."""

from __future__ import annotations

import pytest

from robocal.server.formats import cell_to_json, default_cell
from robocal.server.store import create_campaign, open_database, set_status

# Three poses of the IRB 2600 within its limits, degrees.
POSES_DEG = [
    [0.0, 0.0, 0.0, 0.0, 30.0, 0.0],
    [10.0, 20.0, -10.0, 45.0, -30.0, 90.0],
    [-20.0, 40.0, 20.0, -45.0, 60.0, -90.0],
]


@pytest.fixture
def cell_json() -> dict:
    return cell_to_json(default_cell())


@pytest.fixture
def db(store_url):
    database = open_database(store_url)
    yield database
    database.close()


@pytest.fixture
def running(db, cell_json) -> int:
    """A campaign of three planned poses, started."""
    cid = create_campaign(
        db,
        name="three poses",
        cell_json=cell_json,
        poses_deg=POSES_DEG,
        settings={"settle": "fixed", "pause_s": 1.0, "retries": 2},
    )
    set_status(db, campaign_id=cid, status="running")
    return cid
