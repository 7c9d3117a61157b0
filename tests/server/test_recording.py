"""The Rerun recording of a calibration: written, readable headless, with the expected entities."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

os.environ.setdefault("RERUN_ANALYTICS", "0")

from robocal.drivers.cell import VirtualCell  # noqa: E402
from robocal.server.formats.cell_json import default_cell  # noqa: E402
from robocal.server.recording import _chain, _rms, record_calibration  # noqa: E402
from robocal.server.workflow import run_method  # noqa: E402
from robocal.solver.kinematics import predict  # noqa: E402
from robocal.solver.robot import IRB2600  # noqa: E402

TARGETS = {"A": [60, 0, 35], "B": [-30, 52, 35], "C": [-30, -52, 35]}


def _rerun() -> str:
    exe = shutil.which("rerun") or str(Path(sys.executable).parent / "rerun")
    if not Path(exe).exists():
        pytest.skip("the rerun executable is not installed")
    return exe


def _cli(*args) -> subprocess.CompletedProcess:
    env = dict(os.environ, RERUN_ANALYTICS="0")
    return subprocess.run(
        [_rerun(), "rrd", *args], capture_output=True, text=True, timeout=60, env=env
    )


@pytest.fixture(scope="module")
def campaign():
    cell = default_cell()
    meas = VirtualCell.random(IRB2600, TARGETS, seed=1).campaign(30, seed=1)
    return cell, meas, run_method(cell, meas, "minimax")


def test_recording_reads_back_with_every_entity(campaign, tmp_path):
    cell, meas, cal = campaign
    figure = {
        "name": "joint_offset",
        "label": "joint offset (q2)",
        "x": np.linspace(-1, 1, 30),
        "before": np.sin(np.arange(30.0)),
        "after": np.zeros(30),
        "expected": np.ones(30),
        "x_label": "q2 / deg",
        "y_label": "joint 2 error / mdeg",
    }
    out = record_calibration(
        tmp_path / "sub" / "cal.rrd",
        cell=cell,
        meas=meas,
        calibration=cal,
        diagnosis=SimpleNamespace(figures=[figure]),
    )
    assert out == tmp_path / "sub" / "cal.rrd" and out.stat().st_size > 10_000

    verify = _cli("verify", str(out))
    assert verify.returncode == 0, verify.stderr
    printed = _cli("print", "-vv", str(out))
    assert printed.returncode == 0, printed.stderr
    text = printed.stdout + printed.stderr
    for entity in (
        "world/arm/before",
        "world/arm/after",
        "world/arm/after/flange",
        "world/smr/measured",
        "world/smr/before",
        "world/smr/after",
        "world/error_vectors/before",
        "world/error_vectors/after",
        "errors/rms/before",
        "errors/rms/after",
        "solver/max_F",
        "summary",
        "diagnosis/1_joint_offset/scatter/before",
        "diagnosis/1_joint_offset/figure",
    ):
        assert f"- /{entity} -" in text, entity
    assert "index_name: pose" in text and "index_name: iteration" in text
    assert "EncodedImage:blob" in text


def test_recording_without_history_or_readings(campaign, tmp_path):
    cell, _, _ = campaign
    meas = VirtualCell.random(IRB2600, TARGETS, seed=1).campaign(20, seed=2, beam_break_rate=0.2)
    cal = run_method(cell, meas, "ls-sum")  # no SQP history: no solver series
    out = record_calibration(tmp_path / "ls.rrd", cell=cell, meas=meas, calibration=cal)
    assert _cli("verify", str(out)).returncode == 0
    text = _cli("print", str(out)).stdout
    assert "/world/smr/measured" in text and "/solver/max_F" not in text


def test_chain_ends_at_the_flange_that_carries_the_smrs(campaign):
    _, meas, cal = campaign
    pts, R = _chain(cal, meas.q)
    assert pts.shape == (meas.n_poses, meas.q.shape[1] + 2, 3)
    smr = np.einsum("mij,kj->mki", R, cal.targets) + pts[:, -1, None, :]
    np.testing.assert_allclose(smr, predict(cal.layout, cal.x, meas.q), atol=1e-9)
    np.testing.assert_allclose(pts[:, 0], np.broadcast_to(cal.base[:3, 3], pts[:, 0].shape))


def test_rms_per_pose_skips_missing_readings():
    err = np.array([[[3.0, 4.0, 0.0], [np.nan] * 3], [[np.nan] * 3, [np.nan] * 3]])
    rms = _rms(err)
    assert rms[0] == pytest.approx(5.0) and np.isnan(rms[1])


def test_recording_streams_live_to_a_viewer(tmp_path):
    """A rerun gRPC server on 127.0.0.1 receives the recording while the file is written."""
    import socket
    import time

    from robocal.solver.robot import IRB2600

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    exe = shutil.which("rerun") or str(Path(sys.executable).parent / "rerun")
    # --test-receive: host a gRPC server, take in a recording, exit 0 on the SDK's goodbye
    server = subprocess.Popen(
        [exe, "--test-receive", "--bind", "127.0.0.1", "--port", str(port)],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        env={**os.environ, "RERUN_ANALYTICS": "0"},
    )
    try:
        time.sleep(1.5)
        cell = default_cell()
        meas = VirtualCell.random(
            IRB2600, {k: list(v) for k, v in cell.targets.items()}, seed=2
        ).campaign(12, seed=2)
        cal = run_method(cell, meas, "ls-sum")
        path = record_calibration(
            tmp_path / "local.rrd",
            cell=cell,
            meas=meas,
            calibration=cal,
            viewer_url=f"rerun+http://127.0.0.1:{port}/proxy",
        )
        assert path.stat().st_size > 1000
        assert server.wait(timeout=60) == 0, server.stdout.read()
    finally:
        if server.poll() is None:
            server.kill()
