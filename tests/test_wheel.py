"""The wheel on its own: built from the checkout, installed into a fresh virtual environment
outside it, and run from another directory (the demo, and the service's page and API)."""

from __future__ import annotations

import json
import os
import re
import shutil
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import httpx
import pytest

from tests.server.api.conftest import free_port

ROOT = Path(__file__).resolve().parents[1]


def _uv() -> str:
    uv = shutil.which("uv")
    if uv is None:
        if os.environ.get("CI") == "true":
            pytest.fail("no uv on PATH (CI must have it to test the wheel)")
        pytest.skip("no uv on PATH")
    return uv


def _clean_env(**extra) -> dict[str, str]:
    """The environment without the checkout's venv or import path (so nothing leaks in)."""
    env = {
        k: v
        for k, v in os.environ.items()
        if k not in ("VIRTUAL_ENV", "PYTHONPATH", "PYTHONHOME", "UV_PROJECT_ENVIRONMENT")
        and not k.startswith("ROBOCAL_")
    }
    env.update(RERUN_ANALYTICS="0", **extra)
    return env


def _run(argv, cwd, timeout=600, **kw):
    return subprocess.run(
        [str(a) for a in argv],
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=timeout,
        env=_clean_env(),
        **kw,
    )


@pytest.fixture(scope="module")
def installed(tmp_path_factory):
    """A venv (outside the checkout) with the wheel and the locked dependencies; its bin dir."""
    uv = _uv()
    base = tmp_path_factory.mktemp("wheel")
    assert not base.resolve().is_relative_to(ROOT)
    dist = base / "dist"
    r = _run([uv, "build", "--wheel", "-o", dist], cwd=ROOT)
    assert r.returncode == 0, r.stderr[-2000:]
    (wheel,) = dist.glob("robocal-*.whl")
    # The locked versions, as the image installs them (a fresh resolve could drift).
    reqs = base / "requirements.txt"
    r = _run(
        [uv, "export", "--frozen", "--no-dev", "--no-emit-project", "--no-hashes", "-o", reqs],
        cwd=ROOT,
    )
    assert r.returncode == 0, r.stderr[-2000:]
    venv = base / "venv"
    r = _run([uv, "venv", "--python", sys.executable, venv], cwd=base)
    assert r.returncode == 0, r.stderr[-2000:]
    python = venv / "bin" / "python"
    r = _run([uv, "pip", "install", "--python", python, "-r", reqs, wheel], cwd=base, timeout=900)
    assert r.returncode == 0, r.stderr[-2000:]
    work = base / "elsewhere"
    work.mkdir()
    return venv / "bin", work


def test_wheel_has_one_import_root(installed):
    bin_dir, work = installed
    probe = (
        "import importlib.util as u, json, robocal, robocal.server.cli as c;"
        "print(json.dumps({'top': {n: u.find_spec(n) is not None "
        "for n in ('server', 'solver', 'drivers', 'web', 'migrations')}, "
        "'cli': c.__file__}))"
    )
    r = _run([bin_dir / "python", "-c", probe], cwd=work)
    assert r.returncode == 0, r.stderr
    got = json.loads(r.stdout)
    assert got["top"] == dict.fromkeys(got["top"], False), got
    cli = Path(got["cli"]).resolve()
    assert "site-packages" in cli.parts and not cli.is_relative_to(ROOT), cli
    r = _run([bin_dir / "python", "-c", "import server"], cwd=work)
    assert r.returncode != 0 and "ModuleNotFoundError" in r.stderr, r.stderr


def test_wheel_runs_the_demo_elsewhere(installed):
    bin_dir, work = installed
    r = _run([bin_dir / "robocal", "demo", "--poses", 40, "--holdout", 20, "--out", "d"], cwd=work)
    assert r.returncode == 0, r.stderr[-3000:]
    assert "Table 3" in r.stdout and "held-out RMS: nominal" in r.stdout
    out = work / "d"
    for name in ("robocal.db", "model.json", "model-extended.json", "report.json"):
        assert (out / name).stat().st_size > 0, name
    report = json.loads((out / "report.json").read_text())
    assert report["effects"][0]["name"] == "joint_compliance"
    # the figures written beside the report come with the package's plotting code
    assert list(out.glob("*.png")), sorted(p.name for p in out.iterdir())


def test_wheel_serves_the_page_and_the_api_elsewhere(installed):
    bin_dir, work = installed
    port = free_port()
    db = work / "serve.db"
    proc = subprocess.Popen(
        [
            str(bin_dir / "robocal"),
            "serve",
            "--port",
            str(port),
            "--db",
            str(db),
            "--data-dir",
            str(work / "serve-data"),
        ],
        cwd=work,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        env=_clean_env(),
    )
    try:
        token, seen, deadline = None, [], time.monotonic() + 120
        while time.monotonic() < deadline:
            line = proc.stdout.readline()
            if not line and proc.poll() is not None:
                break
            seen.append(line)
            m = re.search(r"API token \(shown once, keep it\): (\S+)", line)
            token = token or (m.group(1) if m else None)
            if "Uvicorn running" in line:
                break
        assert token, "".join(seen)[-3000:]
        url = f"http://127.0.0.1:{port}"
        page = httpx.get(f"{url}/", timeout=30)
        assert page.status_code == 200 and "<html" in page.text.lower(), page.text[:500]
        assert httpx.get(f"{url}/api/cells", timeout=30).status_code == 401
        cells = httpx.get(
            f"{url}/api/cells", headers={"Authorization": f"Bearer {token}"}, timeout=30
        )
        assert cells.status_code == 200 and cells.json() == ["default"], cells.text
    finally:
        proc.terminate()
        proc.wait(timeout=30)
    # The store's migrations came from the package: the tables and alembic's version are there.
    with sqlite3.connect(db) as con:
        tables = {r[0] for r in con.execute("SELECT name FROM sqlite_master WHERE type='table'")}
        version = con.execute("SELECT version_num FROM alembic_version").fetchall()
    assert "alembic_version" in tables and len(tables) > 2, tables
    assert len(version) == 1, version
