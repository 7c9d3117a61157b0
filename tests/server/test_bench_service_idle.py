"""`robocal bench service`: the idle latency is sampled in turns with the job's, not before it."""

from robocal.server.bench import service


class _Response:
    def __init__(self, body):
        self.body = body

    def json(self):
        return self.body

    def raise_for_status(self):
        return None


class _Client:
    """A service stand-in: each diagnosis job runs for three polls; calls are logged in order."""

    def __init__(self):
        self.log: list[str] = []
        self.polls = 0
        self.jobs = 0

    def post(self, url, json):
        self.jobs += 1
        self.polls = 0
        self.log.append("job")
        return _Response({"id": self.jobs, "state": "queued"})

    def get(self, url):
        if url.startswith("/api/jobs/"):
            self.polls += 1
            return _Response({"state": "running" if self.polls <= 3 else "done"})
        self.log.append("read")
        return _Response({"status": "done"})


def test_idle_spells_surround_every_job():
    c = _Client()
    out = service._during_job(c, 7, rounds=2, idle=5, cap=200)
    spells = "".join("j" if e == "job" else "r" for e in c.log)
    # five idle reads, a job and its 60 reads (three polls of 20), five idle reads, the second
    # job and its reads, five idle reads
    job = "j" + "r" * 60
    assert spells == "r" * 5 + job + "r" * 5 + job + "r" * 5
    assert out["idle"]["requests"] == 15 and out["rounds"] == 2 and out["job"] == "done"
    assert out["requests"] == 120
    assert len(out["load_average_1min"]) == 3
    assert len(out["p50_ms_by_turn"]["idle"]) == 3 and len(out["p50_ms_by_turn"]["job"]) == 2
    for key in ("p25_ms", "p50_ms", "p75_ms", "p99_ms"):
        assert out["idle"][key] >= 0 and out[key] >= 0
