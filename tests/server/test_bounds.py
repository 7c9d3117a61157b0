"""Bounds at parse time: coordinates within a tracker's range, angles within three turns, sizes
and row counts bounded, control characters refused; the CLI and the store refuse cleanly."""

from __future__ import annotations

import json
import subprocess
import sys
import threading
import time
from contextlib import contextmanager

import numpy as np
import pytest

from robocal.server import store
from robocal.server.formats import csv_table, limits
from robocal.server.formats.campaign_csv import read_campaign, write_campaign
from robocal.server.formats.cell_json import cell_to_json, default_cell, parse_cell
from robocal.server.formats.errors import InputError
from robocal.server.formats.model_json import read_model
from robocal.server.store import db as store_db
from robocal.server.store import exchange
from robocal.solver.measurements import Measurements
from robocal.solver.robot import IRB2600

HEADER = "pose,q1,q2,q3,q4,q5,q6,target,x,y,z\n"
ROW = "1,0,0,0,0,30,0,{target},{x},200,300\n"


def meas_text(n_poses=5, x="100.5", target="A", pose="{i}"):
    rows = [
        ROW.format(target=target, x=x).replace("1,", pose.format(i=i) + ",", 1)
        for i in range(1, n_poses + 1)
    ]
    return HEADER + "".join(rows)


def refused(tmp_path, text, name="meas.csv") -> InputError:
    path = tmp_path / name
    path.write_bytes(text.encode())
    with pytest.raises(InputError) as e:
        read_campaign(path, IRB2600)
    print(e.value)
    return e.value


@pytest.mark.parametrize("x", ["1e308", "-1e308", "100000.001", "1e999"])
def test_huge_coordinate_is_refused_with_file_line_column(tmp_path, x):
    e = refused(tmp_path, meas_text(x=x))
    assert (e.line, e.column) == (2, 9) and "column 'x'" in e.message
    assert "out of range" in e.message and "100000" in e.message
    assert len(str(e).splitlines()) == 1


def test_coordinate_at_the_bound_is_accepted(tmp_path):
    path = tmp_path / "meas.csv"
    path.write_text(meas_text(x="-100000"))
    assert read_campaign(path, IRB2600).xyz[0, 0, 0] == -100000.0


@pytest.mark.parametrize("column,value", [("time_s", "1e10"), ("temp_c", "500")])
def test_time_and_temperature_are_bounded(tmp_path, column, value):
    text = meas_text().replace("x,y,z\n", f"x,y,z,{column}\n").replace("300\n", f"300,{value}\n")
    e = refused(tmp_path, text)
    assert e.line == 2 and f"column '{column}'" in e.message


@pytest.mark.parametrize("bad", ["\x00", "\x1b[31m", "\x7f", "a\u2028b", "\t"])
def test_control_characters_in_pose_ids_and_targets_are_refused(tmp_path, bad):
    e = refused(tmp_path, meas_text(pose="p" + bad + "{i}"))
    assert e.line == 2 and "column 'pose'" in e.message and "control character" in e.message
    e = refused(tmp_path, meas_text(target="A" + bad + "B"))
    assert e.line == 2 and "column 'target'" in e.message


def test_rows_beyond_the_limit_are_refused(tmp_path, monkeypatch):
    monkeypatch.setattr(csv_table, "CSV_ROWS_MAX", 10)
    path = tmp_path / "meas.csv"
    path.write_text(meas_text(10))
    read_campaign(path, IRB2600)  # exactly the limit
    e = refused(tmp_path, meas_text(11))
    assert e.line == 12 and "more than 10 data rows" in e.message


def cell_with(**change) -> str:
    cell = cell_to_json(default_cell())
    cell.update(change)
    return json.dumps(cell, indent=1)


@pytest.mark.parametrize(
    "change,field",
    [
        ({"targets": {"A": [1e308, 0, 0]}}, "targets.A[0]"),
        ({"targets": {"A": [0, 0, 100001]}}, "targets.A[2]"),
        ({"base": [[1, 0, 0, 2e5], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]}, "base[0][3]"),
        (
            {
                "robot": {
                    "convention": "dh",
                    "joints": [{"a": 0, "d": 1e300, "theta": 0, "alpha": 0}],
                }
            },
            "robot.joints[0].d",
        ),
        (
            {
                "robot": {
                    "convention": "dh",
                    "joints": [{"a": 0, "d": 0, "theta": 0, "alpha": 0, "limits": [-2000, 2000]}],
                }
            },
            "robot.joints[0].limits[0]",
        ),
        ({"payload_kg": 1e300}, "payload_kg"),
        (
            {
                "robot": {
                    "name": "arm\u0000",
                    "convention": "dh",
                    "joints": [{"a": 0, "d": 0, "theta": 0, "alpha": 0}],
                }
            },
            "robot.name",
        ),
    ],
)
def test_cell_json_numbers_and_names_are_bounded(change, field):
    with pytest.raises(InputError) as e:
        parse_cell(cell_with(**change), "cell.json")
    print(e.value)
    assert e.value.line is not None and e.value.message.startswith(field + ":")


def test_model_json_coordinates_are_bounded(tmp_path):
    model = {
        "schema": 1,
        "robot": json.loads(json.dumps(cell_to_json(default_cell())))["robot"],
        "base": [[1, 0, 0, 1e308], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]],
        "targets": {"A": [0, 0, 0]},
    }
    from robocal.server.formats.cell_json import robot_to_json

    model["robot"] = robot_to_json(IRB2600)
    path = tmp_path / "model.json"
    path.write_text(json.dumps(model, indent=1))
    with pytest.raises(InputError) as e:
        read_model(path)
    assert e.value.message.startswith("base[0][3]:") and "out of range" in e.value.message


def test_oversized_file_is_refused_before_parsing(tmp_path, monkeypatch):
    from robocal.server.formats import files

    monkeypatch.setattr(files, "FILE_BYTES_MAX", 100)
    e = refused(tmp_path, meas_text(5))
    assert e.line is None and "larger than" in e.message


def test_cli_refuses_the_1e308_import_in_one_line(tmp_path):
    (tmp_path / "meas.csv").write_text(meas_text(x="1e308"))
    t0 = time.monotonic()
    r = subprocess.run(
        [
            sys.executable,
            "-m",
            "robocal.server.cli",
            "calibrate",
            "meas.csv",
            "--out",
            "model.json",
        ],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=120,
    )
    print(f"refused in {time.monotonic() - t0:.2f} s: {r.stderr.strip()}")
    assert r.returncode != 0 and "Traceback" not in r.stderr
    assert "meas.csv:2:9" in r.stderr and "out of range" in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "model.json").exists()


# --- chunked import ------------------------------------------------------------------------


def big_campaign(path, n_poses: int) -> None:
    rng = np.random.default_rng(1)
    lo, hi = IRB2600.lower, IRB2600.upper
    q = rng.uniform(lo * 0.5, hi * 0.5, size=(n_poses, 6))
    xyz = rng.uniform(-2000, 2000, size=(n_poses, 3, 3))
    write_campaign(
        path,
        Measurements([str(i + 1) for i in range(n_poses)], q, ("A", "B", "C"), xyz, None, None),
    )


def test_a_large_import_holds_the_write_lock_only_briefly_while_a_campaign_records(
    tmp_path, monkeypatch
):
    """Chunked transactions: the longest write transaction of a 12,000-reading import is far
    below the busy timeout, and a campaign recording readings at the same time never fails."""
    big_campaign(tmp_path / "big.csv", 4000)
    db = store.open_database(tmp_path / "robocal.db")
    cell = cell_to_json(default_cell())
    running = store.create_campaign(
        db, name="recording", cell_json=cell, poses_deg=np.zeros((1, 6)) + [0, 0, 0, 0, 30, 0]
    )
    store.set_status(db, campaign_id=running, status="running")
    durations, lock = [], threading.Lock()
    session = store_db.Database.session

    @contextmanager
    def timed(self, *, write=False):
        t0 = time.perf_counter()
        with session(self, write=write) as s:
            yield s
        if write:
            with lock:
                durations.append(time.perf_counter() - t0)

    monkeypatch.setattr(store_db.Database, "session", timed)
    errors, recorded, stop = [], [0], threading.Event()

    def record():
        # A campaign's reading, rewritten as the engine would retry it: each is a write.
        while not stop.is_set():
            try:
                store.record_reading(
                    db, campaign_id=running, pose_index=0, target="A", xyz=(1.0, 2.0, 3.0)
                )
                recorded[0] += 1
            except Exception as e:  # noqa: BLE001 - any failure is what the test looks for
                errors.append(e)
            time.sleep(0.002)

    worker = threading.Thread(target=record, daemon=True)
    worker.start()
    try:
        cid = store.import_csv(db, path=tmp_path / "big.csv", cell_json=cell, name="big")
    finally:
        stop.set()
        worker.join(timeout=10)
    longest = max(durations)
    print(
        f"import: {len(durations)} write transactions, longest {longest * 1000:.0f} ms "
        f"(busy timeout {store_db.BUSY_TIMEOUT_MS} ms); concurrent writes {recorded[0]}"
    )
    assert not errors and recorded[0] > 0
    # One transaction per IMPORT_CHUNK readings (and the campaign's first and last), each far
    # below the busy timeout a concurrent writer waits.
    assert len(durations) >= 12_000 // exchange.IMPORT_CHUNK + 2
    assert longest < store_db.BUSY_TIMEOUT_MS / 1000
    info = store.get_campaign(db, campaign_id=cid)
    assert (info.status, info.n_poses, info.n_done) == ("done", 4000, 4000)
    total, page = store.readings_page(db, campaign_id=cid, offset=11_998, limit=10)
    assert total == 12_000 and [(p, r.target) for p, r in page] == [("4000", "B"), ("4000", "C")]
    db.close()


def test_a_failed_import_leaves_nothing(tmp_path, monkeypatch):
    big_campaign(tmp_path / "big.csv", 50)
    db = store.open_database(tmp_path / "robocal.db")
    monkeypatch.setattr(exchange, "IMPORT_CHUNK", 30)
    calls = [0]
    real = exchange._add_plan

    def failing(*a, **k):
        calls[0] += 1
        if calls[0] == 3:
            raise RuntimeError("disk full")
        return real(*a, **k)

    monkeypatch.setattr(exchange, "_add_plan", failing)
    with pytest.raises(RuntimeError):
        store.import_csv(
            db, path=tmp_path / "big.csv", cell_json=cell_to_json(default_cell()), name="big"
        )
    assert store.list_campaigns(db) == []
    db.close()


def test_labels_report_their_control_character():
    assert "U+0000" in limits.bad_text("a\x00")
    assert limits.bad_text("pose 1 (élan)") is None
    assert "at most" in limits.bad_text("x" * (limits.LABEL_CHARS_MAX + 1))
