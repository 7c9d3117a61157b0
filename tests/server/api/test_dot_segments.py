"""An API path with dot segments ("/api/fleet/x%2F..") matches no route: a 404 naming the path as
asked, not the file server's normalised one with a 405 that contradicts itself ("/api/fleet
allows GET, HEAD, not GET")."""

from __future__ import annotations

import pytest


@pytest.mark.sqlite_only  # the router's, not the store's
def test_a_path_with_dot_segments_is_no_route(live):
    r = live.client.get("/api/fleet/ur5%2F..")
    assert r.status_code == 404, r.text
    assert r.headers["content-type"] == "application/problem+json"
    assert r.json()["detail"] == "no API route GET /api/fleet/ur5/..", r.json()
    # a method the route does not take still names those it does
    r = live.client.delete("/api/fleet")
    assert r.status_code == 405 and r.headers["allow"] == "GET, HEAD", r.text
