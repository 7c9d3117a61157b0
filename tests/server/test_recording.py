"""The Rerun recording of a calibration: written, readable headless, with the expected entities."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

os.environ.setdefault("RERUN_ANALYTICS", "0")

from robocal.drivers.cell import VirtualCell  # noqa: E402
from robocal.server.calibration.workflow import run_method  # noqa: E402
from robocal.server.formats.cell_json import default_cell  # noqa: E402
from robocal.server.recordings.calibration import _chain, _rms, record_calibration  # noqa: E402
from robocal.server.recordings.cell import PoseSet, color_scale, error_colors  # noqa: E402
from robocal.solver.diagnosis_report import EffectFigure  # noqa: E402
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
    """30 calibration poses and 10 held out, with beam breaks so poses have 1 to 3 readings."""
    cell = default_cell()
    meas = VirtualCell.random(IRB2600, TARGETS, seed=1).campaign(40, seed=1, beam_break_rate=0.15)
    fit, held = meas.subset(np.arange(30)), meas.subset(np.arange(30, 40))
    return cell, fit, held, run_method(cell, fit, "minimax")


def _chunks(path) -> dict[str, list]:
    """Per entity the chunks of the recording read back from the file by the SDK's reader."""
    from rerun.chunk import RrdReader

    out: dict[str, list] = {}
    for ch in RrdReader(str(path)).stream():
        out.setdefault(ch.entity_path, []).append(ch)
    return out


def _static(chunks, entity: str, column: str) -> list:
    """The instances of a static component (one row)."""
    (ch,) = [
        c for c in chunks[entity] if c.is_static and column in c.to_record_batch().schema.names
    ]
    (row,) = ch.to_record_batch().column(column).to_pylist()
    return row


def test_recording_reads_back_with_the_cell_every_pose_and_the_blueprint(campaign, tmp_path):
    cell, meas, held, cal = campaign
    figure = EffectFigure(
        name="joint_offset",
        label="joint offset (q2)",
        x=np.linspace(-1, 1, 30),
        before=np.sin(np.arange(30.0)),
        after=np.zeros(30),
        expected=np.ones(30),
        x_label="q2 / deg",
        y_label="joint 2 error / mdeg",
    )
    out = record_calibration(
        tmp_path / "sub" / "cal.rrd",
        cell=cell,
        meas=meas,
        calibration=cal,
        held_out=held,
        diagnosis=SimpleNamespace(figures=[figure]),
    )
    assert out == tmp_path / "sub" / "cal.rrd" and out.stat().st_size > 10_000

    verify = _cli("verify", str(out))
    assert verify.returncode == 0, verify.stderr
    printed = _cli("print", str(out))
    assert printed.returncode == 0, printed.stderr
    text = printed.stdout + printed.stderr
    static = (
        "world/tracker",
        "world/tracker/head",
        "world/tracker/stand",
        "world/base/nominal",
        "world/base/identified",
        "world/floor",
        "world/floor/grid",
        "world/floor/plane",
        *(
            f"world/poses/{kind}/{what}"
            for kind in ("calibration", "held_out")
            for what in ("measured", "error/before", "error/after")
        ),
        *(f"world/frames/{m}/joint_{j}" for m in ("nominal", "identified") for j in range(1, 7)),
        "world/frames/nominal/links",
        "world/frames/identified/flange",
        "errors/per_pose/calibration/before",
        "errors/per_pose/held_out/after",
        "summary",
        "diagnosis/1_joint_offset/figure",
    )
    for entity in static:
        assert f"- /{entity} -" in text, entity
    # the per-pose entities: one row per pose on the pose timeline, calibration then held-out
    for entity in ("smr/measured", "arm/before", "arm/after/flange", "error/before", "error/after"):
        assert 40 in _rows(text, f"world/pose/{entity}"), entity
    assert 30 in _rows(text, "errors/rms/calibration/after")
    assert 10 in _rows(text, "errors/rms/held_out/before")
    assert len(cal.history) > 2 and len(cal.history) in _rows(text, "solver/max_F")

    # the blueprint: its own store, made active, with the views named and the solver's timeline
    assert "Blueprint" in text and "make_active: true" in text
    verbose = _cli("print", "-vvv", str(out)).stdout
    for view in (
        "cell: every pose, errors coloured by size",
        "one pose at a time (timeline: pose)",
        "nominal and identified frames",
        "solver per iteration (timeline: iteration)",
        "RMS error per pose / mm (bars: before, after)",
        "joint offset (q2)",
    ):
        assert view in verbose, view
    assert "TimePanelBlueprint:timeline" in verbose and "┆ iteration " in verbose

    # every pose at once: one arrow and one point per reading, per kind of pose and model,
    # each arrow 100 x its error and coloured by its size on one scale for both models
    chunks = _chunks(out)
    models = {"before": run_method(cell, meas, "nominal"), "after": cal}
    sets = {k: PoseSet.of(k, m, models) for k, m in (("calibration", meas), ("held_out", held))}
    top = color_scale(list(sets.values()))
    for kind, s in sets.items():
        m = s.meas
        assert len(_static(chunks, f"/world/poses/{kind}/measured", "Points3D:positions")) == (
            m.n_readings
        )
        for model in ("before", "after"):
            entity = f"/world/poses/{kind}/error/{model}"
            vectors = np.array(_static(chunks, entity, "Arrows3D:vectors"))
            assert len(vectors) == m.n_readings
            err = m.xyz - predict(models[model].layout, models[model].x, m.q)
            np.testing.assert_allclose(vectors, 100.0 * err[m.mask], rtol=1e-4, atol=1e-3)
            packed = np.array(_static(chunks, entity, "Arrows3D:colors"), dtype=np.uint32)
            rgb = np.stack([(packed >> 24) & 255, (packed >> 16) & 255, (packed >> 8) & 255], 1)
            expected = error_colors(np.linalg.norm(err[m.mask], axis=-1), top)
            np.testing.assert_array_equal(rgb, expected)
            if model == "before":  # errors of 0.2-3 mm: the colours run the scale
                assert len(np.unique(expected, axis=0)) > 10
            else:  # errors of hundredths of a mm: all green
                assert (expected[:, 1] > 150).all() and (expected[:, 0] < 80).all()
    assert meas.n_readings < 3 * meas.n_poses  # beam breaks: counts are readings, not 3 x poses
    # the floor stands on the identified base; the tracker sits at the origin of the readings
    floor = _static(chunks, "/world/floor", "Transform3D:translation")
    np.testing.assert_allclose(floor[0], cal.base[:3, 3], atol=1e-2)
    assert _static(chunks, "/world/tracker", "Transform3D:translation") == [[0.0, 0.0, 0.0]]
    summary = _static(chunks, "/summary", "TextDocument:text")[0]
    assert "| held_out: 10 |" in summary and "x100" in summary and f"red {top:g} mm" in summary


def _rows(text: str, entity: str) -> set[int]:
    """The row counts of an entity's chunks, as `rerun rrd print` lists them."""
    found = re.findall(rf"with (\d+) rows .* - /{re.escape(entity)} - ", text)
    return {int(n) for n in found}


def test_recording_without_history_or_held_out_poses(campaign, tmp_path):
    cell, meas, _, _ = campaign
    cal = run_method(cell, meas, "ls-sum")  # no SQP history: no solver series
    out = record_calibration(tmp_path / "ls.rrd", cell=cell, meas=meas, calibration=cal)
    assert _cli("verify", str(out)).returncode == 0
    text = _cli("print", str(out)).stdout
    assert "/world/poses/calibration/error/after" in text and "/solver/max_F" not in text
    assert "/world/poses/held_out" not in text
    chunks = _chunks(out)
    summary = _static(chunks, "/summary", "TextDocument:text")[0]
    assert "no held-out poses" in summary
    verbose = _cli("print", "-vvv", str(out)).stdout
    assert "┆ pose " in verbose and "solver per iteration" not in verbose


def test_error_colours_run_green_yellow_red():
    c = error_colors(np.array([0.0, 0.5, 1.0, 7.0, np.nan]), top=1.0)
    assert c.dtype == np.uint8 and c.shape == (5, 3)
    green, yellow, red = c[0], c[1], c[2]
    assert green[1] > green[0] and yellow[0] > 200 and yellow[1] > 150 and red[0] > 3 * red[1]
    assert (c[3] == red).all() and (c[4] == red).all()  # beyond the scale, or unknown: red


def test_colour_scale_tops_the_nominal_errors_on_a_1_2_5_step(campaign):
    cell, meas, _, cal = campaign
    models = {"before": run_method(cell, meas, "nominal"), "after": cal}
    s = PoseSet.of("calibration", meas, models)
    top = color_scale([s])
    p95 = np.nanpercentile(np.linalg.norm(s.err["before"], axis=-1), 95)
    assert p95 <= top < 2.5 * p95
    assert round(top / 10 ** np.floor(np.log10(top)), 9) in (1.0, 2.0, 5.0)


def test_chain_ends_at_the_flange_that_carries_the_smrs(campaign):
    _, meas, _, cal = campaign
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


def test_a_diagnosis_recording_shows_the_final_model_after_and_the_geometric_beside(tmp_path):
    """The demo's recording of a diagnosis: "after" is the final, extended model (its errors as
    `evaluate` gives them), the geometric calibration beside it under its own entities."""
    from robocal.server.calibration import workflow
    from tests.server.test_validation_model import campaign as effect_campaign

    cell, meas = effect_campaign(50, 21, ("joint_compliance:2",))
    fit, held = meas.subset(np.arange(40)), meas.subset(np.arange(40, 50))
    cal = run_method(cell, fit, "ls-sum")
    d, model = workflow.diagnose(cell, fit, screen=False)
    assert d.extensions, "the diagnosis found the compliance"
    out = record_calibration(
        tmp_path / "d.rrd", cell=cell, meas=fit, calibration=cal, held_out=held, extended=model
    )
    text = _cli("print", str(out)).stdout
    for entity in (
        "world/poses/held_out/error/geometric",
        "world/frames/geometric/links",
        "errors/per_pose/calibration/geometric",
    ):
        assert f"- /{entity} -" in text, entity
    for entity in ("arm/geometric", "error/after", "error/geometric"):
        assert 50 in _rows(text, f"world/pose/{entity}"), entity
    chunks = _chunks(out)
    for kind, m in (("calibration", fit), ("held_out", held)):
        after = np.array(_static(chunks, f"/world/poses/{kind}/error/after", "Arrows3D:vectors"))
        geo = np.array(_static(chunks, f"/world/poses/{kind}/error/geometric", "Arrows3D:vectors"))
        rms_after = np.sqrt(np.mean(np.sum((after / 100.0) ** 2, axis=-1)))
        rms_geo = np.sqrt(np.mean(np.sum((geo / 100.0) ** 2, axis=-1)))
        assert rms_after == pytest.approx(workflow.evaluate(model, m).model.rmse, rel=1e-3)
        e = np.linalg.norm(m.xyz - predict(cal.layout, cal.x, m.q), axis=-1)
        assert rms_geo == pytest.approx(np.sqrt(np.nanmean(e * e)), rel=1e-3)
        assert rms_after < 0.7 * rms_geo, (kind, rms_after, rms_geo)
    summary = _static(chunks, "/summary", "TextDocument:text")[0]
    assert f"after: the diagnosis's final model **{d.report.final.model}**" in summary
    assert "| RMS before | RMS after | RMS geometric |" in summary


def test_robocal_diagnose_writes_its_recording_with_the_final_model_after(tmp_path):
    """`robocal diagnose --recording`: the final model "after", the geometry beside it, the
    summary naming the final model the report names."""
    import json

    from robocal.server.formats.campaign_csv import write_campaign
    from tests.server.test_validation_model import campaign as effect_campaign

    _, meas = effect_campaign(40, 21, ("joint_compliance:2",))  # the default cell's
    csv, out = tmp_path / "meas.csv", tmp_path / "d.rrd"
    write_campaign(csv, meas)
    run = subprocess.run(
        [sys.executable, "-m", "robocal.server.cli", "diagnose", str(csv)]
        + ["--out", str(tmp_path / "report.json"), "--recording", str(out)],
        capture_output=True,
        text=True,
        timeout=600,
        env=dict(os.environ, RERUN_ANALYTICS="0"),
    )
    assert run.returncode == 0, run.stderr
    assert f"rerun recording to {out}" in " ".join(run.stdout.split())
    final = json.loads((tmp_path / "report.json").read_text())["final"]["model"]
    chunks = _chunks(out)
    assert "/world/frames/geometric/links" in chunks
    summary = _static(chunks, "/summary", "TextDocument:text")[0]
    assert f"after: the diagnosis's final model **{final}**" in summary
