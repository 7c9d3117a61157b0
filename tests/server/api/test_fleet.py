"""A fleet on one PostgreSQL database: two stations start together (the schema is made once) and
run and import campaigns at the same time, losing and duplicating no reading."""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

from tests.backends import execute, fresh_postgres
from tests.server.api.conftest import serve, settings_for, wait_for

POSES = 8
TARGETS = {"A", "B", "C"}


def run(live, name: str, seed: int) -> tuple[int, dict]:
    """Plan and run a simulated campaign on this station; its id and final state."""
    c = live.client
    body = {"name": name, "poses": POSES, "seed": seed, "pause_s": 0.0, "samples": 5}
    r = c.post("/api/campaigns", json=body)
    assert r.status_code == 201, r.text
    cid = r.json()["id"]
    assert c.post(f"/api/campaigns/{cid}/start").status_code == 202
    done = wait_for(
        lambda: c.get(f"/api/campaigns/{cid}").json(),
        lambda j: j["status"] not in ("planned", "running") and not (j["run"] or {}).get("active"),
    )
    assert done["status"] == "done" and done["poses_done"] == POSES, done
    return cid, done


def imported(live, csv_text: str, name: str) -> int:
    r = live.client.post(f"/api/measurements/import?name={name}", content=csv_text)
    assert r.status_code == 201, r.text
    return r.json()["id"]


def rows(database: str, cid: int) -> dict[tuple[int, str], int]:
    """How many stored rows each (pose, target) of the campaign has."""
    found = execute(
        database,
        "SELECT pose_index, target, count(*) FROM reading WHERE campaign_id = :c "
        "GROUP BY pose_index, target",
        c=cid,
    )
    return {(i, t): n for i, t, n in found}


def measured(live, cid: int) -> dict:
    return {
        (m["pose"], m["target"]): (m["status"], m["xyz"])
        for m in live.client.get(f"/api/campaigns/{cid}/measurements").json()
    }


def test_two_stations_share_one_database(tmp_path):
    with fresh_postgres() as url:
        servers = [serve(settings_for(tmp_path / name, url)) for name in ("north", "south")]
        # Both start (and migrate) at once: the second waits for the first's schema.
        with ThreadPoolExecutor(2) as pool:
            north, south = pool.map(next, servers)
        try:
            assert execute(url, "SELECT version_num FROM alembic_version") == [("0012",)]
            tables = execute(
                url,
                "SELECT table_name FROM information_schema.tables "
                "WHERE table_schema = 'public' ORDER BY table_name",
            )
            assert [t for (t,) in tables] == sorted(
                [
                    "alembic_version",
                    "campaign",
                    "job",
                    "model_check",
                    "planned_pose",
                    "pose_outcome",
                    "reading",
                ]
            )

            # Round 1: each station runs a campaign, both at once.
            with ThreadPoolExecutor(2) as pool:
                (n1, n1_done), (s1, s1_done) = pool.map(
                    lambda a: run(*a), [(north, "north-1", 1), (south, "south-1", 2)]
                )
            north_csv = north.client.get(f"/api/campaigns/{n1}/measurements.csv").text
            south_csv = south.client.get(f"/api/campaigns/{s1}/measurements.csv").text

            # Round 2: each runs another while importing the other's first, all at once.
            with ThreadPoolExecutor(4) as pool:
                runs = pool.map(lambda a: run(*a), [(north, "north-2", 3), (south, "south-2", 4)])
                imports = pool.map(
                    lambda a: imported(*a),
                    [(north, south_csv, "from-south"), (south, north_csv, "from-north")],
                )
                (n2, n2_done), (s2, s2_done) = runs
                n_imp, s_imp = imports

            ids = [n1, s1, n2, s2, n_imp, s_imp]
            assert len(set(ids)) == len(ids), ids
            # Both stations see every campaign of the fleet.
            for live in (north, south):
                listed = {c["id"] for c in live.client.get("/api/campaigns").json()}
                assert set(ids) <= listed, (ids, listed)

            # Every (pose, target) a station ran is stored exactly once, as many as it reported.
            for cid, done in [(n1, n1_done), (s1, s1_done), (n2, n2_done), (s2, s2_done)]:
                stored = rows(url, cid)
                assert set(stored.values()) == {1}, (cid, stored)
                assert set(stored) == {(i, t) for i in range(POSES) for t in TARGETS}, cid
                summary = done["run"]["summary"]
                assert summary["readings"] + summary["missing"] == len(stored), summary
            # An import holds what the other station measured, once each.
            assert measured(north, n_imp) == measured(south, s1)
            assert measured(south, s_imp) == measured(north, n1)
            for cid in (n_imp, s_imp):
                assert set(rows(url, cid).values()) == {1}
            total = execute(url, "SELECT count(*) FROM reading")[0][0]
            assert total == sum(len(rows(url, cid)) for cid in ids)
        finally:
            for server in servers:
                server.close()
