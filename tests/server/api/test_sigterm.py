"""SIGTERM of the service mid-campaign with a slow request in flight: STOP reaches the controller
before the listener closes; Ctrl-C of `robocal acquire` sends STOP before it exits."""

from __future__ import annotations

import json
import re
import signal
import socket
import sqlite3
import subprocess
import sys
import threading
import time
from pathlib import Path

import httpx

from tests.server.api.conftest import free_port, wait_for
from tests.server.api.test_real_devices import cell_json, devices  # noqa: F401 - a fixture

ROOT = Path(__file__).resolve().parents[3]
SLOW = {"poses": 12, "pause_s": 0.5, "samples": 20, "order": True, "seed": 2}


class Wire:
    """Times (monotonic) at which each line reached the simulated controller."""

    def __init__(self, controller):
        self.lines: list[tuple[float, str]] = []
        handle = controller.handle_line

        def handle_line(line):
            self.lines.append((time.monotonic(), line.strip()))
            return handle(line)

        controller.handle_line = handle_line

    def first(self, word: str, after: float = 0.0) -> float | None:
        return next((t for t, line in list(self.lines) if f" {word}" in line and t >= after), None)


def start_service(tmp_path, port):
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "robocal.server.cli",
            "serve",
            "--port",
            str(port),
            "--db",
            str(tmp_path / "s.db"),
            "--data-dir",
            str(tmp_path / "data"),
        ],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    out: list[str] = []
    token, deadline = None, time.monotonic() + 60
    while time.monotonic() < deadline:
        line = proc.stdout.readline()
        out.append(line)
        m = re.search(r"API token \(shown once, keep it\): (\S+)", line)
        token = token or (m.group(1) if m else None)
        if "Uvicorn running" in line:
            threading.Thread(target=lambda: out.extend(proc.stdout), daemon=True).start()
            return proc, token, out
    proc.kill()
    raise RuntimeError("service did not start: " + "".join(out))


def listener_closed(port, closed: dict, stop: threading.Event):
    """Record when connecting to the port is first refused."""
    while not stop.is_set():
        try:
            with socket.create_connection(("127.0.0.1", port), timeout=0.5):
                pass
        except OSError:
            closed["t"] = time.monotonic()
            return
        time.sleep(0.002)


def test_sigterm_stops_the_arm_before_the_listener_closes(tmp_path, devices):
    wire = Wire(devices.controller)
    port = free_port()
    proc, token, out = start_service(tmp_path, port)
    url = f"http://127.0.0.1:{port}/api"
    auth = {"Authorization": f"Bearer {token}"}
    try:
        with httpx.Client(headers=auth, timeout=30) as c:
            cell_id = c.post(f"{url}/cells", json=cell_json(devices)).json()["id"]
            cid = c.post(
                f"{url}/campaigns", json={"name": "term", "cell_id": cell_id, **SLOW}
            ).json()["id"]
            assert c.post(f"{url}/campaigns/{cid}/start").status_code == 202
            wait_for(
                lambda: len(devices.controller.moves), lambda n: n >= 2, timeout=60, interval=0.01
            )
        # The slow request: an event stream held open, which the drain waits for.
        stream = httpx.Client(headers=auth, timeout=httpx.Timeout(30, read=None))
        opened = threading.Event()

        def follow():
            try:
                with stream.stream("GET", f"{url}/events") as r:
                    opened.set()
                    for _ in r.iter_lines():
                        pass
            except httpx.HTTPError:
                pass

        threading.Thread(target=follow, daemon=True).start()
        assert opened.wait(10)
        closed, stop = {}, threading.Event()
        watcher = threading.Thread(target=listener_closed, args=(port, closed, stop), daemon=True)
        watcher.start()
        moves_before = len(devices.controller.moves)
        t_signal = time.monotonic()
        proc.send_signal(signal.SIGTERM)
        proc.wait(timeout=30)
        t_exit = time.monotonic()
        stop.set()
        watcher.join(timeout=5)
        stream.close()
    finally:
        if proc.poll() is None:
            proc.kill()
    t_stop = wire.first("STOP", after=t_signal)
    assert t_stop is not None, "no STOP reached the controller"
    assert "t" in closed, "the listener never closed"
    print(
        f"\nSIGTERM -> STOP on the wire {1000 * (t_stop - t_signal):.1f} ms, listener closed "
        f"{1000 * (closed['t'] - t_signal):.1f} ms, process exited "
        f"{1000 * (t_exit - t_signal):.0f} ms after the signal"
    )
    assert t_stop < closed["t"], "the listener closed before the arm was stopped"
    moves_after = [t for t, line in wire.lines if " MOVEJ" in line and t > t_stop]
    assert moves_after == [] and len(devices.controller.moves) == moves_before
    # uvicorn ends by re-raising the signal it caught, so the process dies of SIGTERM
    assert proc.returncode in (0, -signal.SIGTERM), "".join(out)
    con = sqlite3.connect(tmp_path / "s.db")
    status, owner = con.execute("SELECT status, lease_owner FROM campaign").fetchone()
    con.close()
    assert (status, owner) == ("estopped", None), "".join(out)
    assert any("SIGTERM: campaign" in line and "e-stopped" in line for line in out), out


def ctrl_c_as_at_a_terminal():
    """In the child before it starts: SIGINT at its default, as a terminal's foreground job has
    it. A shell's background job (`nohup`, `&`: how a loaded CI box may run the suite) inherits it
    ignored, and Python then never raises KeyboardInterrupt: the run went on, the test hung."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def test_ctrl_c_of_acquire_sends_stop_then_resumes_with_reset(tmp_path, devices):
    wire = Wire(devices.controller)
    cell = tmp_path / "cell.json"
    cell.write_text(json.dumps(cell_json(devices)))
    args = [
        sys.executable,
        "-m",
        "robocal.server.cli",
        "acquire",
        "--db",
        str(tmp_path / "a.db"),
        "--cell",
        str(cell),
        "--name",
        "cc",
        "--poses",
        "8",
        "--pause",
        "0.3",
        "--seed",
        "2",
    ]
    proc = subprocess.Popen(
        args,
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=ctrl_c_as_at_a_terminal,
    )
    try:
        wait_for(lambda: len(devices.controller.moves), lambda n: n >= 2, timeout=60, interval=0.01)
        moves = len(devices.controller.moves)
        t_signal = time.monotonic()
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
    t_stop = wire.first("STOP", after=t_signal)
    assert t_stop is not None, err
    print(f"\nCtrl-C -> STOP on the wire {1000 * (t_stop - t_signal):.1f} ms")
    assert proc.returncode == 130, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "STOP sent" in lines[0] and "--reset" in lines[0], err
    assert len(devices.controller.moves) <= moves + 1  # at most the move already on its way
    con = sqlite3.connect(tmp_path / "a.db")
    assert con.execute("SELECT status FROM campaign").fetchone() == ("estopped",)
    before = con.execute("SELECT count(*) FROM reading").fetchone()[0]
    con.close()
    # Without --reset it refuses (one line); with it the campaign completes, nothing twice.
    wait_for(devices.world.moving, lambda moving: not moving, timeout=10, interval=0.02)
    again = subprocess.run(args, cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert again.returncode == 1 and "e-stopped" in again.stderr, again.stderr
    assert len(again.stderr.strip().splitlines()) == 1
    done = subprocess.run(args + ["--reset"], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    con = sqlite3.connect(tmp_path / "a.db")
    status = con.execute("SELECT status FROM campaign").fetchone()[0]
    rows, distinct = con.execute(
        "SELECT count(*), count(DISTINCT pose_index || target) FROM reading"
    ).fetchone()
    con.close()
    assert status == "done" and rows == distinct == 24 and rows >= before
