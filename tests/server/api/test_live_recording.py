"""A campaign's recording in pieces (GET /api/campaigns/{id}/recording?from_pose=N): each piece
the poses finished since the last one, all of one recording, as the page's viewer adds them."""

from __future__ import annotations

import re

from tests.server.api.conftest import wait_for
from tests.server.test_recording import _cli


def test_pieces_add_up_to_the_campaign(live, tmp_path):
    c = live.client
    cid = c.post("/api/campaigns", json={"poses": 6, "pause_s": 0}).json()["id"]
    before = c.get(f"/api/campaigns/{cid}/recording")
    assert before.status_code == 200 and before.headers["X-Next-Pose"] == "0"
    assert before.content  # the layout and the tracker, before any pose
    assert c.post(f"/api/campaigns/{cid}/start").status_code == 202
    status = wait_for(lambda: c.get(f"/api/campaigns/{cid}").json()["status"], "done".__eq__)
    assert status == "done"
    head = c.get(f"/api/campaigns/{cid}/recording?from_pose=0")
    tail = c.get(f"/api/campaigns/{cid}/recording?from_pose=4")
    none = c.get(f"/api/campaigns/{cid}/recording?from_pose=6")
    assert head.headers["X-Next-Pose"] == tail.headers["X-Next-Pose"] == "6"
    assert none.content == b"" and none.headers["X-Next-Pose"] == "6"
    # the first 4 poses from one piece, the last 2 from another: one recording, every pose once
    first4 = c.get(f"/api/campaigns/{cid}/recording?from_pose=0").content
    out = tmp_path / "pieces.rrd"
    out.write_bytes(first4 + tail.content)
    printed = _cli("print", "-v", str(out))
    assert printed.returncode == 0, printed.stderr
    text = printed.stdout
    assert f"robocal-campaign-{cid}" in text
    poses = set(re.findall(r"/world/readings/pose_(\d{5})", text))
    assert poses == {f"{i:05d}" for i in range(6)}, text[:2000]
    assert live.anonymous.get(f"/api/campaigns/{cid}/recording").status_code == 401
    assert c.get("/api/campaigns/999/recording").status_code == 404
