"""Campaigns as arrays and meas.csv files: export, import (all or nothing), round trips."""

from __future__ import annotations

import numpy as np
import pytest
from sqlalchemy import text

from robocal.drivers.cell import VirtualCell
from robocal.server.formats import InputError, read_campaign, write_campaign
from robocal.server.store import (
    StoreError,
    campaign_measurements,
    create_campaign,
    export_csv,
    export_lines,
    get_campaign,
    import_csv,
    planned_poses,
    pose_readings,
    record_missing,
    record_pose_outcome,
    record_reading,
    set_status,
)
from robocal.solver.robot import IRB2600
from tests.robots import TARGETS

TABLES = ("campaign", "planned_pose", "reading", "pose_outcome")


@pytest.fixture(scope="module")
def simulated():
    """A simulated campaign with beam breaks, timed, with air temperature."""
    cell = VirtualCell.random(IRB2600, TARGETS, seed=11)
    return cell.campaign(25, seed=12, beam_break_rate=0.15)


def store_like_an_engine(db, cell_json, meas) -> int:
    """Record a campaign reading by reading, as the campaign engine would."""
    q_deg = np.rad2deg(meas.q)
    cid = create_campaign(
        db,
        name="engine",
        cell_json=cell_json,
        poses_deg=q_deg,
        settings={"seed": 12},
        simulated=True,
    )
    set_status(db, campaign_id=cid, status="running")
    for i in range(meas.n_poses):
        for k, t in enumerate(meas.target_names):
            if meas.mask[i, k]:
                record_reading(
                    db,
                    campaign_id=cid,
                    pose_index=i,
                    target=t,
                    xyz=meas.xyz[i, k],
                    std=[0.002] * 3,
                    samples=20,
                    time_s=meas.time_s[i, k],
                    temp_c=meas.temp_c[i, k],
                )
            else:
                record_missing(
                    db, campaign_id=cid, pose_index=i, target=t, detail="beam break after 3 retries"
                )
        state = "measured" if meas.mask[i].all() else "missing-target"
        record_pose_outcome(db, campaign_id=cid, pose_index=i, state=state, reached_deg=q_deg[i])
    set_status(db, campaign_id=cid, status="done")
    return cid


def assert_same(a, b, mm=0.0, deg=0.0):
    assert list(a.pose_ids) == list(b.pose_ids)
    assert a.target_names == b.target_names
    np.testing.assert_allclose(np.rad2deg(a.q), np.rad2deg(b.q), rtol=0, atol=deg)
    np.testing.assert_array_equal(a.mask, b.mask)
    np.testing.assert_allclose(a.xyz, b.xyz, rtol=0, atol=mm)
    for x, y in ((a.time_s, b.time_s), (a.temp_c, b.temp_c)):
        assert (x is None) == (y is None)
        if x is not None:
            np.testing.assert_allclose(x, y, rtol=0, atol=mm)


def dump(db) -> dict:
    with db.session() as s:
        return {t: s.execute(text(f"SELECT * FROM {t} ORDER BY id")).all() for t in TABLES}


def test_measurements_are_what_was_recorded(db, cell_json, simulated):
    assert 0 < simulated.n_readings < simulated.xyz.shape[0] * simulated.xyz.shape[1]
    keep = simulated.mask.any(axis=1)  # a pose with every beam broken has no row in meas.csv
    cid = store_like_an_engine(db, cell_json, simulated)
    meas = campaign_measurements(db, campaign_id=cid, robot=IRB2600)
    assert_same(meas, simulated.subset(keep), deg=1e-12)
    np.testing.assert_array_equal(meas.xyz, simulated.subset(keep).xyz)  # bit for bit


def test_round_trip_export_import(tmp_path, db, cell_json, simulated):
    cid = store_like_an_engine(db, cell_json, simulated)
    before = campaign_measurements(db, campaign_id=cid)
    export_csv(db, campaign_id=cid, path=tmp_path / "meas.csv", robot=IRB2600)
    assert_same(read_campaign(tmp_path / "meas.csv", IRB2600), before, mm=5e-7, deg=5e-10)

    back = import_csv(
        db, path=tmp_path / "meas.csv", robot=IRB2600, cell_json=cell_json, name="imported"
    )
    info = get_campaign(db, campaign_id=back)
    assert (info.status, info.n_done, info.n_poses) == ("done", before.n_poses, before.n_poses)
    assert info.settings == {"source": "csv", "file": "meas.csv"}
    after = campaign_measurements(db, campaign_id=back, robot=IRB2600)
    assert_same(after, before, mm=5e-7, deg=5e-10)  # within the file's print precision
    # and the imported campaign exports the same file again
    export_csv(db, campaign_id=back, path=tmp_path / "again.csv")
    assert (tmp_path / "again.csv").read_text() == (tmp_path / "meas.csv").read_text()


def test_an_imported_files_prev_q_is_kept(tmp_path, db, cell_json, simulated):
    """A file split or reordered gives prev_q (the joints the arm came from) on some poses: the
    store keeps them, the campaign's readings give them back and export them again."""
    keep = simulated.mask.any(axis=1)
    meas = simulated.subset(keep)
    rng = np.random.default_rng(5)
    prev = meas.q + np.deg2rad(rng.uniform(-20, 20, meas.q.shape))
    prev[::3] = np.nan  # poses without: the visit order says
    meas.prev_q = prev
    write_campaign(tmp_path / "meas.csv", meas)
    cid = import_csv(db, path=tmp_path / "meas.csv", cell_json=cell_json, name="split")
    back = campaign_measurements(db, campaign_id=cid, robot=IRB2600)
    assert back.prev_q is not None and np.isnan(back.prev_q[::3]).all()
    given = np.isfinite(prev[:, 0])
    np.testing.assert_allclose(back.prev_q[given], prev[given], atol=1e-10)
    export_csv(db, campaign_id=cid, path=tmp_path / "again.csv")
    assert (tmp_path / "again.csv").read_text() == (tmp_path / "meas.csv").read_text()
    streamed = "".join(export_lines(db, campaign_id=cid, chunk=7))  # the service's export
    assert streamed == (tmp_path / "meas.csv").read_text()
    plain = import_csv(db, path=_without_prev(tmp_path), cell_json=cell_json, name="plain")
    assert campaign_measurements(db, campaign_id=plain).prev_q is None
    assert "prev_q1" not in next(export_lines(db, campaign_id=plain))


def _without_prev(tmp_path):
    """The same campaign's file with no prev_q columns."""
    meas = read_campaign(tmp_path / "meas.csv", IRB2600)
    meas.prev_q = None
    write_campaign(tmp_path / "plain.csv", meas)
    return tmp_path / "plain.csv"


def test_import_records_absent_targets_as_missing(tmp_path, db, cell_json, simulated):
    write_campaign(tmp_path / "meas.csv", simulated)
    cid = import_csv(db, path=tmp_path / "meas.csv", cell_json=cell_json, name="sim")
    poses = planned_poses(db, campaign_id=cid)
    kept = simulated.mask.any(axis=1)
    for pose, mask in zip(poses, simulated.mask[kept], strict=True):
        assert pose.state == ("measured" if mask.all() else "missing-target")
        readings = pose_readings(db, campaign_id=cid, pose_index=pose.index)
        assert [readings[t].status for t in simulated.target_names] == [
            "ok" if m else "missing" for m in mask
        ]


@pytest.mark.parametrize(
    "bad, match",
    [
        ("x", "not a number"),  # a non-numeric coordinate on the last line
        ("duplicate", "already on line"),
        ("limits", "outside the limits"),
    ],
)
def test_bad_csv_import_leaves_the_database_unchanged(
    tmp_path, db, cell_json, simulated, bad, match
):
    store_like_an_engine(db, cell_json, simulated)
    write_campaign(tmp_path / "meas.csv", simulated)
    lines = (tmp_path / "meas.csv").read_text().splitlines()
    fields = lines[-1].split(",")
    if bad == "x":
        fields[lines[0].split(",").index("x")] = "12.5mm"
        lines[-1] = ",".join(fields)
    elif bad == "duplicate":
        lines.append(lines[-1])
    else:
        fields[lines[0].split(",").index("q3")] = "120.0"
        lines[-1] = ",".join(fields)
    (tmp_path / "bad.csv").write_text("\n".join(lines) + "\n")
    before = dump(db)
    with pytest.raises(InputError, match=match) as err:
        import_csv(db, path=tmp_path / "bad.csv", robot=IRB2600, cell_json=cell_json, name="bad")
    assert err.value.line is not None
    assert dump(db) == before


def test_bad_cell_or_robot_leaves_the_database_unchanged(tmp_path, db, cell_json, simulated):
    write_campaign(tmp_path / "meas.csv", simulated)
    with pytest.raises(InputError, match="unknown robot"):
        import_csv(
            db, path=tmp_path / "meas.csv", cell_json='{"robot": "x", "targets": {}}', name="bad"
        )
    with pytest.raises(InputError, match="cannot read"):
        import_csv(db, path=tmp_path / "none.csv", cell_json=cell_json, name="bad")
    assert dump(db) == {t: [] for t in TABLES}


def test_measurements_of_a_campaign_in_progress(tmp_path, running, db):
    meas = campaign_measurements(db, campaign_id=running)
    assert (meas.n_poses, meas.target_names, meas.time_s) == (0, (), None)
    with pytest.raises(StoreError, match="no readings"):
        export_csv(db, campaign_id=running, path=tmp_path / "empty.csv")
    record_reading(db, campaign_id=running, pose_index=1, target="C", xyz=[1, 2, 3])
    meas = campaign_measurements(db, campaign_id=running)
    # the pose has no outcome yet, so its joints are the planned ones
    assert meas.pose_ids == ["2"] and meas.target_names == ("C",)
    np.testing.assert_allclose(np.rad2deg(meas.q[0]), [10.0, 20.0, -10.0, 45.0, -30.0, 90.0])
    assert meas.time_s is None and meas.temp_c is None
    # in the order a campaign engine names its targets, unread ones as NaN
    meas = campaign_measurements(db, campaign_id=running, targets=["C", "A"])
    assert meas.target_names == ("C", "A")
    assert np.isfinite(meas.xyz[0, 0]).all() and np.isnan(meas.xyz[0, 1]).all()
