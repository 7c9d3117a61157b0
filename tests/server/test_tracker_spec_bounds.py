"""A tracker spec past any laser tracker's (another unit) is refused at its key: 10,000 um took a
one-SMR UR10-like campaign's held-out error from 0.0165 to 0.908 mm under its prior, 'deployable';
0.01 um (mm typed for um) made a clean fit 'an effect the model lacks' at 1,170x its floor."""

import json

import pytest

from robocal.server.cli import main

from .test_cf_open_turn import _cell as ur10_like


def _cell(tracker=None) -> dict:
    """The UR10-like arm of test_cf_open_turn, one SMR off the flange axis."""
    cell = {**ur10_like([(-360, 360)] * 6), "targets": {"A": [30.0, 10.0, 40.0]}}
    return cell if tracker is None else {**cell, "tracker": tracker}


@pytest.mark.parametrize(
    ("tracker", "key", "said"),
    [
        (
            {"mpe_um": 0.01, "mpe_um_per_m": 0.0025},
            "tracker.mpe_um",
            "0.01 um is no laser tracker's MPE",
        ),
        ({"mpe_um": 10000}, "tracker.mpe_um", "nm typed for um?"),
        ({"mpe_um": 10, "mpe_um_per_m": 2500}, "tracker.mpe_um_per_m", "2500 um/m is no laser"),
    ],
)
def test_a_spec_past_any_tracker_is_refused(tmp_path, capsys, tracker, key, said):
    sim, bad = tmp_path / "sim.json", tmp_path / "cell.json"
    sim.write_text(json.dumps(_cell()))
    bad.write_text(json.dumps(_cell(tracker)))
    meas = str(tmp_path / "meas.csv")
    assert (
        main(["simulate", "--cell", str(sim), "--poses", "30", "--seed", "5", "--out", meas]) == 0
    )
    capsys.readouterr()
    args = [
        "calibrate",
        meas,
        "--cell",
        str(bad),
        "--method",
        "ls-sum",
        "--out",
        str(tmp_path / "m.json"),
    ]
    assert main(args) == 1
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"robocal: error: {bad}:") and f"{key}: " in err and said in err, err


def test_real_trackers_specs_are_taken(tmp_path):
    for tracker in ({"mpe_um": 15, "mpe_um_per_m": 6}, {"mpe_um": 0, "mpe_um_per_m": 2.5}):
        path = tmp_path / "cell.json"
        path.write_text(json.dumps(_cell(tracker)))
        meas = str(tmp_path / "meas.csv")
        assert main(["simulate", "--cell", str(path), "--poses", "10", "--out", meas]) == 0
