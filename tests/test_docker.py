"""The container: its files stay in step with the repository, its dependency step installs from
the lock as it stands, and, where a Docker daemon answers, the image is built and run for real.

The image test talks to loopback only: the service container shares the host's network and
listens on 127.0.0.1 (a second one, with no network at all, is asked from inside itself).
"""

from __future__ import annotations

import json
import os
import re
import shlex
import shutil
import subprocess
import time
import uuid
from pathlib import Path

import httpx
import pytest

from tests.server.api.conftest import free_port

ROOT = Path(__file__).resolve().parents[1]
DOCKERFILE = ROOT / "docker" / "Dockerfile"
COMPOSE = ROOT / "docker" / "compose.yaml"
# The base image: python:3.11-slim from Docker Hub unless told otherwise (docker/local-base.sh
# builds a stand-in from Debian packages where Docker Hub is out of reach).
BASE = os.environ.get("ROBOCAL_DOCKER_BASE", "python:3.11-slim")


def instructions():
    """The Dockerfile as (INSTRUCTION, arguments), continuation lines joined, comments dropped."""
    text = re.sub(r"\\\n", " ", DOCKERFILE.read_text())
    out = []
    for line in text.splitlines():
        line = line.strip()
        if line and not line.startswith("#"):
            word, _, rest = line.partition(" ")
            out.append((word.upper(), rest.strip()))
    return out


def copied():
    return {
        src.rstrip("/")
        for word, rest in instructions()
        if word == "COPY"
        for src in rest.split()[:-1]
        if not src.startswith("--")
    }


def test_dockerfile_copies_existing_paths():
    for src in copied():
        assert (ROOT / src).exists(), f"Dockerfile copies missing {src}"


def test_dockerfile_copies_what_the_installed_service_reads():
    """The wheel's packages and the directories the code finds beside them (page, migrations)."""
    import tomllib

    from robocal.server.service.web import WEB_DIR
    from robocal.server.store.db import MIGRATIONS

    pyproject = tomllib.loads((ROOT / "pyproject.toml").read_text())
    needed = set(pyproject["tool"]["hatch"]["build"]["targets"]["wheel"]["packages"])
    needed |= {p.relative_to(ROOT).as_posix() for p in (MIGRATIONS, WEB_DIR)}
    needed |= {"pyproject.toml", "uv.lock", pyproject["project"]["readme"]}
    assert needed <= copied(), f"not copied into the image: {sorted(needed - copied())}"


def test_image_starts_without_uv_run():
    """`uv run` at start rebuilds the project and fetches its build backend: a container with no
    network (or PyPI down) would not start. The command must be the venv's own entry point."""
    cmd = [rest for word, rest in instructions() if word == "CMD"][-1]
    argv = json.loads(cmd) if cmd.startswith("[") else shlex.split(cmd)
    assert argv[0] != "uv", f"CMD {argv} runs through uv"
    env = " ".join(rest for word, rest in instructions() if word == "ENV")
    assert "/app/.venv/bin" in env, "the venv's bin is not on the image's PATH"


def test_image_runs_the_installed_package_not_the_sources():
    """The project step installs the wheel's layout into the venv (no editable link to /app)."""
    steps = [rest for word, rest in instructions() if word == "RUN" and rest.startswith("uv sync")]
    project = [s for s in steps if "--no-install-project" not in s]
    assert project and all("--no-editable" in s for s in project), steps


def test_lock_is_current_and_installs_for_the_image(tmp_path):
    """`uv sync --frozen` in the image trusts uv.lock blindly: it must match pyproject.toml, and
    the non-dev set must resolve for Python 3.11 on Linux (what the image's two sync steps do)."""
    uv = shutil.which("uv")
    if uv is None:
        pytest.skip("no uv on PATH")
    r = subprocess.run(
        [uv, "lock", "--check"], cwd=ROOT, capture_output=True, text=True, timeout=120
    )
    assert r.returncode == 0, f"uv.lock is stale for pyproject.toml: {r.stderr.strip()}"
    steps = [rest for word, rest in instructions() if word == "RUN" and rest.startswith("uv sync")]
    assert steps, "no `uv sync` step in the Dockerfile"
    for step in steps:
        assert "--frozen" in step and "--no-dev" in step, step
    r = subprocess.run(
        [uv, "sync", "--frozen", "--no-dev", "--no-install-project", "--dry-run"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=300,
        env={**os.environ, "UV_PROJECT_ENVIRONMENT": str(tmp_path / "venv")},
    )
    assert r.returncode == 0, r.stderr
    plan = set(re.findall(r"^ \+ ([\w.-]+)==", r.stderr + r.stdout, re.M))
    assert {"fastapi", "uvicorn", "numpy"} <= plan and not plan & {"pytest", "playwright"}, plan


def test_compose_publishes_on_loopback_with_a_data_volume():
    text = COMPOSE.read_text()
    ports = re.findall(r'^\s*-\s*"([^"]+:8000)"\s*$', text, re.M)
    assert ports and all(p.startswith("127.0.0.1:") for p in ports), ports
    assert re.search(r"^\s*-\s*robocal-data:/data\s*$", text, re.M)
    assert re.search(r"^volumes:\s*\n\s+robocal-data:", text, re.M)
    assert "dockerfile: docker/Dockerfile" in text and "context: .." in text


# ---- the real image, where a daemon answers -------------------------------------------------


def _docker(*args, timeout=120, check=True):
    r = subprocess.run(["docker", *args], capture_output=True, text=True, timeout=timeout)
    if check:
        assert r.returncode == 0, f"docker {' '.join(args)}: {r.stderr.strip()[-2000:]}"
    return r


def _last_line(text: str) -> str:
    lines = [ln for ln in text.strip().splitlines() if ln.strip()]
    return lines[-1] if lines else "(no output)"


@pytest.fixture(scope="module")
def image():
    if shutil.which("docker") is None:
        pytest.skip("no docker command")
    info = subprocess.run(
        ["docker", "info", "--format", "{{.ServerVersion}}"],
        capture_output=True,
        text=True,
        timeout=30,
    )
    if info.returncode != 0:
        pytest.skip(f"no Docker daemon: {_last_line(info.stderr)}")
    if _docker("image", "inspect", BASE, check=False).returncode != 0:
        pull = _docker("pull", BASE, timeout=300, check=False)
        if pull.returncode != 0:
            pytest.skip(
                f"base image {BASE} not available: {_last_line(pull.stderr)} "
                "(ROBOCAL_DOCKER_BASE names another; docker/local-base.sh builds one)"
            )
    tag = "robocal:pytest"
    # Host network for the build's downloads: it works whether or not the daemon has a bridge.
    _docker(
        "build",
        "--network",
        "host",
        "-f",
        str(DOCKERFILE),
        "--build-arg",
        f"PYTHON_IMAGE={BASE}",
        "-t",
        tag,
        str(ROOT),
        timeout=1800,
    )
    yield tag


@pytest.fixture
def volume():
    name = f"robocal-pytest-{uuid.uuid4().hex[:8]}"
    _docker("volume", "create", name)
    yield name
    _docker("volume", "rm", "-f", name, check=False)


def _run(image, volume, *args):
    name = f"robocal-pytest-{uuid.uuid4().hex[:8]}"
    r = _docker("run", "-d", "--name", name, "-v", f"{volume}:/data", *args, image, check=False)
    if r.returncode != 0:
        _docker("rm", "-f", name, check=False)  # a container created but not started
        raise AssertionError(f"docker run {name}: {r.stderr.strip()[-2000:]}")
    return name


def _wait(get, what, timeout=60.0):
    deadline = time.monotonic() + timeout
    while True:
        try:
            return get()
        except (httpx.HTTPError, AssertionError) as e:
            if time.monotonic() > deadline:
                raise AssertionError(f"{what}: {e}") from e
            time.sleep(0.5)


def test_image_serves_on_loopback_keeps_its_data_and_starts_offline(image, volume):
    port = free_port()
    url = f"http://127.0.0.1:{port}"
    containers = []
    try:
        # The host's network, the service on its loopback only (the image's default is 0.0.0.0,
        # for a published port).
        ctr = _run(
            image,
            volume,
            "--network",
            "host",
            "-e",
            "ROBOCAL_HOST=127.0.0.1",
            "-e",
            f"ROBOCAL_PORT={port}",
        )
        containers.append(ctr)

        def health():
            r = httpx.get(f"{url}/api/health", timeout=5)  # open; the data needs the token
            assert r.status_code == 200, r.text
            return r.json()

        assert _wait(health, f"GET /api/health of {ctr}") == {"status": "ok"}
        logs = _docker("logs", ctr).stdout + _docker("logs", ctr).stderr
        tokens = re.findall(r"API token \(shown once, keep it\): (\S+)", logs)
        assert len(tokens) == 1, logs[-2000:]
        auth = {"Authorization": f"Bearer {tokens[0]}"}
        assert httpx.get(f"{url}/api/cells").status_code == 401
        assert httpx.get(f"{url}/api/cells", headers=auth).json() == ["default"]
        assert httpx.post(f"{url}/api/campaigns", json={"poses": 5}).status_code == 401
        r = httpx.post(f"{url}/api/campaigns", json={"poses": 5, "name": "kept"}, headers=auth)
        assert r.status_code == 201, r.text
        # The database and the data directory are on the volume, written by the service's user.
        ls = _docker(
            "exec",
            ctr,
            "sh",
            "-c",
            "id -un; test -s /data/robocal.db && test -d /data/robocal-data && echo ok",
        )
        user, ok = ls.stdout.split()
        assert user != "root" and ok == "ok", ls.stdout

        # A new container on the same volume: the campaign is there and the token is not reissued.
        _docker("rm", "-f", containers.pop())
        ctr = _run(
            image,
            volume,
            "--network",
            "host",
            "-e",
            "ROBOCAL_HOST=127.0.0.1",
            "-e",
            f"ROBOCAL_PORT={port}",
        )
        containers.append(ctr)
        _wait(health, f"GET /api/health of {ctr}")
        assert [c["name"] for c in httpx.get(f"{url}/api/campaigns", headers=auth).json()] == [
            "kept"
        ]
        assert (
            httpx.post(f"{url}/api/campaigns", json={"poses": 5}, headers=auth).status_code == 201
        )
        assert "API token" not in _docker("logs", ctr).stdout + _docker("logs", ctr).stderr

        # No network at all: the service still starts (nothing fetched at start); asked from
        # inside its own container, on the image's default 0.0.0.0:8000.
        _docker("rm", "-f", containers.pop())
        ctr = _run(image, volume, "--network", "none")
        containers.append(ctr)
        probe = (
            "import urllib.request; print(urllib.request.urlopen(urllib.request.Request("
            f"'http://127.0.0.1:8000/api/campaigns', headers={auth!r}), timeout=4)"
            ".read().decode())"
        )
        got = _wait(
            lambda: json.loads(_docker("exec", ctr, "python3", "-c", probe).stdout),
            f"the offline container {ctr}",
        )
        assert len(got) == 2
    finally:
        for c in containers:
            _docker("rm", "-f", c, check=False)
