"""Two services on one SQLite file asked for the same calibration at once queue it once: the
duplicate check is in the insert's write transaction, not only behind each service's own lock
(before, both answered 202 and the calibration ran twice)."""

from __future__ import annotations

import threading

import httpx
import pytest

from robocal.server.service.settings import Settings
from tests.real import import_real
from tests.server.api.conftest import ONE_CONNECTION_A_REQUEST, free_port, serve

PAIRS = 12


@pytest.mark.sqlite_only  # PostgreSQL's advisory lock is the same write lock (store/db.py)
def test_one_calibration_queued_from_two_services_at_once(tmp_path):
    db = str(tmp_path / "robocal.db")
    first = serve(Settings(database=db, data_dir=tmp_path / "a", port=free_port()))
    a = next(first)
    second = serve(Settings(database=db, data_dir=tmp_path / "b", port=free_port()))
    b = next(second)
    try:
        cid = import_real(a.client, "irb120_wu")
        clients = [
            httpx.Client(
                base_url=s.url,
                headers={"Authorization": f"Bearer {s.token}"},
                timeout=60,
                limits=ONE_CONNECTION_A_REQUEST,
            )
            for s in (a, b)
        ]
        for pair in range(PAIRS):  # each pair another calibration: its own tolerance
            body = {"campaign_id": cid, "method": "nominal", "tolerance_mm": 1.0 + pair}
            start = threading.Barrier(2)
            answers: list[httpx.Response] = [None, None]

            def ask(i, body=body, start=start, answers=answers):
                start.wait()
                answers[i] = clients[i].post("/api/jobs", json=body)

            threads = [threading.Thread(target=ask, args=(i,)) for i in range(2)]
            for t in threads:
                t.start()
            for t in threads:
                t.join()
            codes = sorted(r.status_code for r in answers)
            assert codes == [202, 409], [r.text for r in answers]
            made = next(r for r in answers if r.status_code == 202).json()["id"]
            refused = next(r for r in answers if r.status_code == 409).json()
            assert refused["job_id"] == made, refused
        jobs = a.client.get("/api/jobs").json()
        assert len(jobs) == PAIRS, [(j["id"], j["method"]) for j in jobs]
        for c in clients:
            c.close()
    finally:
        for gen in (second, first):  # on to the end of serve(): the server stopped
            next(gen, None)
