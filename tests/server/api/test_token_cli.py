"""The token: shown once the service listens, never lost unseen; `robocal token reset` makes a
new one that a running service takes at once (issue 14, item 5)."""

import re
import signal
import socket
import subprocess
import sys
import time

import httpx

from tests.server.api.conftest import free_port
from tests.server.test_cli import robocal

TOKEN = re.compile(r"API token \(shown once, keep it\): (\S+)")


def start(tmp_path, port):
    """`robocal serve` until it says it runs: the process, the token it showed, its lines."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "robocal.server.cli", "serve", "--port", str(port)]
        + ["--db", "s.db", "--data-dir", "data"],
        cwd=tmp_path,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    lines, deadline = [], time.monotonic() + 120
    while time.monotonic() < deadline:
        line = proc.stdout.readline()
        lines.append(line)
        if "Uvicorn running" in line:
            m = TOKEN.search("".join(lines))
            return proc, (m.group(1) if m else None), lines
        if not line and proc.poll() is not None:
            break
    proc.kill()
    raise RuntimeError("service did not start: " + "".join(lines))


def stop(proc):
    proc.send_signal(signal.SIGINT)
    proc.communicate(timeout=60)


def test_a_busy_port_shows_no_token_and_loses_none(tmp_path):
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        r = robocal("serve", "--port", port, "--db", "s.db", "--data-dir", "data", cwd=tmp_path)
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 1 and len(lines) == 1, r.stderr
    assert f"cannot listen on 127.0.0.1:{port}" in lines[0] and "--port" in lines[0]
    assert not TOKEN.search(r.stderr + r.stdout)
    assert not (tmp_path / "data" / "token.sha256").exists()
    # the port free again: the first start that listens shows the token, which works
    proc, token, _ = start(tmp_path, port)
    try:
        assert token
        h = {"Authorization": f"Bearer {token}"}
        assert httpx.get(f"http://127.0.0.1:{port}/api/campaigns", headers=h).status_code == 200
    finally:
        stop(proc)


def test_token_reset_replaces_the_token_of_a_running_service(tmp_path):
    port = free_port()
    proc, old, _ = start(tmp_path, port)
    try:
        url = f"http://127.0.0.1:{port}/api/campaigns"
        assert httpx.get(url, headers={"Authorization": f"Bearer {old}"}).status_code == 200
        r = robocal("token", "reset", "--data-dir", "data", cwd=tmp_path)
        assert r.returncode == 0, r.stderr
        new = r.stdout.strip()
        assert new and new != old and len(new.splitlines()) == 1
        assert "token.sha256" in r.stderr and "at once" in r.stderr
        # no restart needed: the service reads the hash on each request
        assert httpx.get(url, headers={"Authorization": f"Bearer {old}"}).status_code == 401
        assert httpx.get(url, headers={"Authorization": f"Bearer {new}"}).status_code == 200
    finally:
        stop(proc)
    # a later start shows no token, but says where it is kept and how to get a new one
    proc, again, lines = start(tmp_path, port)
    stop(proc)
    assert again is None
    hint = "".join(lines)
    assert "robocal token reset --data-dir data" in hint and "token.sha256" in hint
    r = robocal("token", "show", "--data-dir", "data", cwd=tmp_path)
    assert r.returncode == 0 and "token.sha256" in r.stdout and "token reset" in r.stdout
    assert new not in r.stdout
