"""A done job's charts and Table 3 are drawn once and kept: the second answer is the kept one,
byte for byte; another database behind the same data directory (a job of the same id) never
gets them."""

from __future__ import annotations

import json
import time
from pathlib import Path

import httpx

from tests.server.api.conftest import serve, settings_for, wait_for
from tests.server.test_cli import robocal

CHARTS = ("boxplot.png", "errors.png", "table3")
ARTIFACT = Path(__file__).parents[2] / "web" / "artifacts" / "chart-cache-reopen.json"


def _timed_get(c, url: str) -> tuple[httpx.Response, float]:
    t0 = time.perf_counter()
    r = c.get(url)
    return r, time.perf_counter() - t0


def _calibrated(c, csv: str) -> int:
    r = c.post("/api/measurements/import", content=csv, params={"filename": "train.csv"})
    assert r.status_code == 201, r.text
    r = c.post("/api/jobs", json={"campaign_id": r.json()["id"], "method": "ls-sum"})
    assert r.status_code == 202, r.text
    job = wait_for(
        lambda: c.get(f"/api/jobs/{r.json()['id']}").json(),
        lambda j: j["state"] in ("done", "failed"),
    )
    assert job["state"] == "done", job
    return job["id"]


def test_charts_drawn_once_and_kept_per_job_and_database(tmp_path):
    r = robocal("simulate", "--poses", 25, "--seed", 3, "--out", "train.csv", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    csv = (tmp_path / "train.csv").read_text()
    first = settings_for(tmp_path)
    served = serve(first)
    live = next(served)
    token = live.token  # the data directory's: the second service reads the same token file
    try:
        job = _calibrated(live.client, csv)
        seconds: dict[str, dict[str, float]] = {"first_open": {}, "reopen": {}}
        for chart in CHARTS:
            a, seconds["first_open"][chart] = _timed_get(
                live.client, f"/api/charts/jobs/{job}/{chart}"
            )
            b, seconds["reopen"][chart] = _timed_get(live.client, f"/api/charts/jobs/{job}/{chart}")
            assert a.status_code == b.status_code == 200, (a.text, b.text)
            assert (a.headers["x-robocal-cache"], b.headers["x-robocal-cache"]) == ("miss", "hit")
            assert a.content == b.content, chart
        # the figure the issue asks for (a reopened job's charts within 1 s), shown, not asserted
        # (timing on a shared machine): the kept answers next to the first drawing, same run
        figures = {
            "reopen_s": round(sum(seconds["reopen"].values()), 4),
            "first_open_s": round(sum(seconds["first_open"].values()), 4),
            "per_chart_s": {k: {c: round(t, 4) for c, t in v.items()} for k, v in seconds.items()},
            "target_s": 1.0,
        }
        print(json.dumps({"chart_cache_reopen": figures}))
        ARTIFACT.parent.mkdir(exist_ok=True)
        ARTIFACT.write_text(json.dumps(figures, indent=2) + "\n")
        assert len(list((first.data_dir / "charts").iterdir())) == 1
    finally:
        served.close()
    # another database, the same data directory: its job 1 is another job, drawn anew
    other = settings_for(tmp_path, str(tmp_path / "other.db"))
    assert other.data_dir == first.data_dir
    served = serve(other)
    live = next(served)
    c = httpx.Client(base_url=live.url, headers={"Authorization": f"Bearer {token}"}, timeout=60)
    try:
        job2 = _calibrated(c, csv)
        assert job2 == job
        for chart in CHARTS:
            r = c.get(f"/api/charts/jobs/{job2}/{chart}")
            assert r.status_code == 200 and r.headers["x-robocal-cache"] == "miss", chart
        assert len(list((first.data_dir / "charts").iterdir())) == 2
    finally:
        c.close()
        served.close()
