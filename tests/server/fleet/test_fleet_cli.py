"""`robocal fleet` on a database of twelve simulated arms: the table names the bent arm, --out
writes the view; an unknown robot model or database is one line and a non-zero exit."""

from __future__ import annotations

import json

import pytest

from robocal.server import store
from tests.server.fleet.arms import ARMS, BENT, build_fleet
from tests.server.test_cli import robocal


@pytest.fixture(scope="module")
def fleet_db(tmp_path_factory):
    d = tmp_path_factory.mktemp("fleet")
    with store.open_database(d / "fleet.db") as db:
        build_fleet(db, d)
    return d


def test_the_table_names_the_bent_arm(fleet_db):
    r = robocal("fleet", "irb2600", "--db", "fleet.db", "--out", "fleet.json", cwd=fleet_db)
    assert r.returncode == 0, r.stderr
    flagged = [line for line in r.stdout.splitlines() if line.startswith("SN-")]
    assert len(flagged) == 2 and all(line.startswith(f"{BENT}: a2 ") for line in flagged)
    view = json.loads((fleet_db / "fleet.json").read_text())
    assert len(view["arms"]) == ARMS
    assert [a["arm"] for a in view["arms"] if a["flagged"] or a["jumped"]] == [BENT]


def test_the_models_are_listed(fleet_db):
    r = robocal("fleet", "--db", "fleet.db", cwd=fleet_db)
    assert r.returncode == 0 and f"irb2600: {ARMS} arms" in r.stdout, r.stderr


@pytest.mark.parametrize(
    ("args", "said"),
    [
        (("irb120", "--db", "fleet.db"), "no calibrated arm of robot model 'irb120'"),
        (("irb2600", "--db", "nowhere/x.txt"), "nowhere"),
    ],
)
def test_bad_input_is_one_line(fleet_db, args, said):
    r = robocal("fleet", *args, cwd=fleet_db)
    assert r.returncode != 0 and len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert said in r.stderr and "Traceback" not in r.stderr, r.stderr
