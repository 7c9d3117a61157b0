"""Every mistake one clear line: each bad input named on one line of stderr, a non-zero exit,
never a traceback (issue 14, item 7), and the `robocal token` command."""

import json
import subprocess
import sys

import numpy as np
import pytest

from tests.server.api.conftest import free_port

from .test_cli import robocal


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """A small campaign as CSV and in a database, its model, and files that are not what is
    asked for: a folder, an empty file, a CSV named .db, a database with a planned campaign."""
    d = tmp_path_factory.mktemp("mistakes")
    for args in (
        ("simulate", "--poses", 30, "--seed", 2, "--out", "meas.csv"),
        ("calibrate", "meas.csv", "--out", "model.json"),
        ("acquire", "--db", "a.db", "--poses", 30, "--pause", 0, "--seed", 2),
    ):
        r = robocal(*args, cwd=d)
        assert r.returncode == 0, r.stderr
    (d / "folder").mkdir()
    (d / "empty.csv").write_text("")
    (d / "empty.json").write_text("")
    (d / "fake.db").write_bytes((d / "meas.csv").read_bytes())
    lines = (d / "meas.csv").read_text().splitlines(keepends=True)
    (d / "two_smrs.csv").write_text("".join(x for x in lines if ",C," not in x))
    (d / "poses.csv").write_text("pose,q1,q2,q3,q4,q5,q6\n1,0,10,0,0,20,0\n")
    (d / "targets.csv").write_text("pose,target,x,y,z,q1,q2,q3,q4,q5,q6\n1,A,0,0,0,0,0,0,0,0,0\n")
    model = (d / "model.json").read_text().rstrip().removesuffix("}")
    # past the JSON parser's own recursion limit, and below it in a file with a mistake (whose
    # placing walked the document recursively)
    (d / "deep.json").write_text(model + ', "notes": ' + "[" * 5000 + "]" * 5000 + "}")
    bad = model.replace('"schema": 1', '"schema": 2', 1)
    (d / "deep_bad.json").write_text(bad + ', "notes": ' + "[" * 600 + "]" * 600 + "}")
    zero = json.loads((d / "model.json").read_text())
    zero["base"] = [[0.0, 0.0, 0.0, 1000.0], [0.0] * 4, [0.0] * 4, [0.0, 0.0, 0.0, 1.0]]
    (d / "zero_base.json").write_text(json.dumps(zero, indent=2))
    reflected = json.loads((d / "model.json").read_text())
    reflected["base"][2] = [-v for v in reflected["base"][2][:3]] + [reflected["base"][2][3]]
    (d / "mirror_base.json").write_text(json.dumps(reflected, indent=2))
    # blocks the program reads back from a model (the deployment verdict, the parameter table's
    # standard errors): a hand edit of the wrong type was a traceback, "no" was deployable
    for name, key, value, _ in META_EDITS:
        edited = json.loads((d / "model.json").read_text())
        edited[key] = value
        (d / name).write_text(json.dumps(edited, indent=2))
    from robocal.server import store

    with store.open_database(d / "a.db") as a:
        cell = store.get_campaign(a, campaign_id=1).cell_json
    with store.open_database(d / "planned.db") as db:
        store.create_campaign(db, name="later", cell_json=cell, poses_deg=np.full((4, 6), 10.0))
    return d


META_EDITS = [
    ("rows.json", "identified", {"rows": [1]}, "identified.rows[0]: expected an object"),
    (
        "deployable.json",
        "validation",
        {"deployable": "no"},
        "validation.deployable: expected true or false",
    ),
    ("reasons.json", "validation", {"deployable": False, "reasons": [1]}, "validation.reasons[0]"),
    ("uncertainty.json", "uncertainty", "x", "uncertainty: expected an object"),
    ("fixed.json", "fit", {"fixed_parameters": 3}, "fit.fixed_parameters: expected an object"),
    ("errors.json", "uncertainty", {"standard_errors": {"a1": "0.1"}}, "standard_errors.a1"),
    # a negative or non-finite error figure in the verdict was read as if written by the program
    (
        "negative_rms.json",
        "validation",
        {"deployable": True, "holdout_rms_mm": -0.02},
        "validation.holdout_rms_mm: -0.02 is below the minimum 0",
    ),
    (
        "nan_floor.json",
        "validation",
        {"deployable": True, "noise_floor_mm": float("nan")},
        "validation.noise_floor_mm: nan is not a finite number",
    ),
    (
        "negative_fit.json",
        "validation",
        {"deployable": True, "fit_rms_mm": -1},
        "validation.fit_rms_mm: -1 is below the minimum 0",
    ),
]


def one_line_error(r, *words):
    """The run failed with one line on stderr that holds every word."""
    lines = r.stderr.strip().splitlines()
    assert r.returncode != 0, r.stdout
    assert len(lines) == 1, r.stderr
    assert "Traceback" not in r.stderr
    for w in words:
        assert w in lines[0], lines[0]
    return lines[0]


CASES = [
    # the cases
    (("calibrate", "a.db", "--campaign", 7), ["a.db", "no campaign 7", "1 ("]),
    (("calibrate", "planned.db"), ["planned.db", "campaign 1 (later)", "no measured pose"]),
    (("diagnose", "planned.db", "--campaign", 1), ["planned.db", "planned"]),
    (("compare", "planned.db"), ["planned.db", "no measured pose"]),
    (("acquire", "--db", "meas.csv", "--poses", 3, "--pause", 0), ["meas.csv", "not a database"]),
    (("acquire", "--db", "empty.csv", "--poses", 3, "--pause", 0), ["empty.csv", "not a database"]),
    (("acquire", "--db", "folder", "--poses", 3, "--pause", 0), ["folder", "is a folder"]),
    (("calibrate", "fake.db"), ["fake.db", "not a SQLite database"]),
    (("diagnose", "fake.db"), ["fake.db", "not a SQLite database"]),
    (("simulate", "--poses", 0, "--out", "x.csv"), ["--poses", "'0' is not a positive integer"]),
    (("simulate", "--poses", -3, "--out", "x.csv"), ["--poses", "'-3'"]),
    (("simulate", "--poses", "ten", "--out", "x.csv"), ["--poses", "'ten' is not a whole number"]),
    (("acquire", "--poses", 0), ["--poses", "'0'"]),
    (("serve", "--port", 80000), ["--port", "'80000' is not a TCP port"]),
    # more of the same kind
    (("simulate", "--beam-break-rate", 2, "--out", "x.csv"), ["--beam-break-rate", "'2'"]),
    (("simulate", "--beam-break-rate", -1, "--out", "x.csv"), ["--beam-break-rate", "'-1'"]),
    (("simulate", "--poses", 3, "--out", "folder"), ["folder", "is a folder"]),
    (("simulate", "--poses", 3, "--out", "nowhere/x.csv"), ["nowhere/x.csv", "no folder"]),
    (("calibrate", "meas.csv", "--out", "folder"), ["folder", "is a folder"]),
    (("calibrate", "meas.csv", "--campaign", 1), ["meas.csv", "--campaign", "database"]),
    (("calibrate", "meas.csv", "--method", "minmax"), ["did you mean 'minimax'?"]),
    (("calibrate", "meas.csv", "--method", "ls-sun"), ["did you mean 'ls-sum'?"]),
    # what the data lacks for a method was said without naming the data
    (
        ("calibrate", "two_smrs.csv", "--method", "ls-pose"),
        ["two_smrs.csv: ls-pose needs at least three SMRs", "has 2 (A, B)"],
    ),
    (
        ("calibrate", "two_smrs.csv", "--method", "ls-single:C"),
        ["two_smrs.csv: method 'ls-single:C': no target 'C'"],
    ),
    (("calibrat", "meas.csv"), ["invalid choice: 'calibrat'", "did you mean 'calibrate'?"]),
    (("calibrate", "missing.csv"), ["missing.csv", "No such file"]),
    (("calibrate", "missing.db"), ["missing.db", "no such file"]),
    (("calibrate", "folder"), ["folder", "Is a directory"]),
    (("calibrate", "empty.csv"), ["empty.csv", "empty file"]),
    (("calibrate", "model.json"), ["model.json"]),
    (("calibrate", "meas.csv", "--cell", "empty.json"), ["empty.json", "empty file"]),
    (("evaluate", "model.json", "missing.csv"), ["missing.csv", "No such file"]),
    (("evaluate", "model.json", "a.db", "--campaign", 9), ["a.db", "no campaign 9"]),
    (("evaluate", "meas.csv", "meas.csv"), ["meas.csv", "invalid JSON"]),
    (("evaluate", "folder", "meas.csv"), ["folder", "Is a directory"]),
    (("predict", "empty.json", "poses.csv"), ["empty.json", "empty file"]),
    (("predict", "model.json", "empty.csv"), ["empty.csv", "empty file"]),
    (("predict", "model.json", "poses.csv", "--out", "folder"), ["folder", "is a folder"]),
    (("compensate", "model.json", "missing.csv"), ["missing.csv"]),
    (("export", "missing.json", "--out", "x.csv"), ["missing.json"]),
    (("acquire", "--pause", -1, "--poses", 3), ["--pause", "'-1'"]),
    (("acquire", "--choose-from", -1, "--poses", 3), ["--choose-from", "'-1'"]),
    (("acquire", "--verify", "model.json", "--directions", 7), ["--directions", "'7'"]),
    (("acquire", "--verify", "model.json", "--cycles", 0), ["--cycles", "'0'"]),
    (("demo", "--holdout", 0), ["--holdout", "'0'"]),
    (
        ("simulate", "--poses", 3, "--out", "x.csv", "--effect", "joint_complance:2"),
        ["unknown effect 'joint_complance'", "did you mean 'joint_compliance'?"],
    ),
    # an effect past any real cell's (a typo, or another unit) was simulated as given
    (
        ("simulate", "--poses", 3, "--out", "x.csv", "--effect", "base_shift=1e9"),
        ["'base_shift=1e9'", "1e+09 mm is past any real cell's base_shift", "0 to 100 mm"],
    ),
    (
        ("simulate", "--poses", 3, "--out", "x.csv", "--effect", "joint_scale:2=-2e4"),
        ["-20000 ppm", "bound -10000 to 10000 ppm"],
    ),
    (("bench", "solver", "--sizes", 0), ["--sizes", "'0'"]),
    (("schema", "modle"), ["did you mean 'model'?"]),
    (("calibrate", "meas.csv", "--recording", "folder"), ["folder", "is a folder"]),
    (("serve", "--data-dir", "meas.csv", "--db", "s.db"), ["meas.csv", "data folder is a file"]),
    (("token", "reset", "--data-dir", "meas.csv"), ["meas.csv", "data folder is a file"]),
    (("token", "rest"), ["did you mean 'reset'?"]),
    (("serve", "--db", "folder"), ["folder", "is a folder"]),
    (("acquire", "--cell", "meas.csv", "--poses", 3), ["meas.csv", "invalid JSON"]),
    (("export", "model.json", "--out", "x.xyz"), ["x.xyz", "--format"]),
    (("calibrate", "mysql://host/db"), ["mysql://host/db", "SQLite files and PostgreSQL"]),
    (("calibrate", "::://"), ["not a database file or URL"]),
    (("simulate", "--posess", 3, "--out", "x.csv"), ["--posess", "did you mean --poses?"]),
    # another command's option is named as such, never "did you mean" itself
    (
        ("evaluate", "model.json", "meas.csv", "--cell", "c.json"),
        ["--cell is not an option of robocal evaluate"],
    ),
    # issue 20: a model nested too deeply, or whose base is no rotation, by every reader
    *[
        (tuple(model if a == "MODEL" else a for a in cmd), [model, why])
        for cmd in (
            ("compensate", "MODEL", "targets.csv", "--out", "j.csv"),
            ("export", "MODEL", "--format", "params", "--out", "p.csv"),
            ("predict", "MODEL", "poses.csv", "--out", "pred.csv"),
            ("evaluate", "MODEL", "meas.csv"),
            ("acquire", "--db", "v.db", "--pause", 0, "--verify", "MODEL"),
        )
        for model, why in (
            ("deep.json", "nested too deeply"),
            ("deep_bad.json", "nested too deeply"),
            ("zero_base.json", "base: rotation part is not orthonormal"),
            ("mirror_base.json", "base: rotation part is a reflection"),
        )
    ],
    (("calibrate", "meas.csv", "--cell", "deep.json"), ["deep.json", "nested too deeply"]),
    *[
        ((*cmd, "negative_rms.json", *rest), ["negative_rms.json", "holdout_rms_mm", "minimum 0"])
        for cmd, rest in (
            (("predict",), ("poses.csv", "--out", "pred.csv")),
            (("evaluate",), ("meas.csv",)),
            (("check",), ("meas.csv",)),
        )
    ],
    *[
        ((cmd, name, *rest), [name, why])
        for name, _, _, why in META_EDITS
        for cmd, *rest in (
            ("export", "--format", "params", "--out", "p.csv"),
            ("compensate", "targets.csv", "--out", "j.csv"),
        )
    ],
]


@pytest.mark.parametrize("args,words", CASES, ids=[" ".join(map(str, a)) for a, _ in CASES])
def test_a_mistake_is_one_line(files, args, words):
    one_line_error(robocal(*args, cwd=files), *words)


def test_an_unreachable_database_is_one_line_without_its_password(files):
    url = f"postgresql+psycopg://robocal:secret@127.0.0.1:{free_port()}/robocal"
    line = one_line_error(robocal("calibrate", url, cwd=files), "cannot open the database")
    assert "secret" not in line and "***" in line


def test_nothing_half_written_on_a_mistake(files):
    """A refused run leaves no output file behind."""
    r = robocal("simulate", "--poses", 0, "--out", "never.csv", cwd=files)
    assert r.returncode != 0 and not (files / "never.csv").exists()
    assert not (files / "meas.db").exists()  # `acquire --db meas.csv` made no database either


def test_evaluate_reads_a_database_as_calibrate_does(files):
    """`evaluate model.json a.db --campaign N` gives the figures of that campaign exported."""
    from robocal.server import store

    with store.open_database(files / "a.db") as db:
        store.export_csv(db, campaign_id=1, path=files / "a.csv")
    r = robocal("evaluate", "model.json", "a.db", "--campaign", 1, "--json", "db.json", cwd=files)
    assert r.returncode == 0, r.stderr
    r = robocal("evaluate", "model.json", "a.csv", "--json", "csv.json", cwd=files)
    assert r.returncode == 0, r.stderr
    from_db = json.loads((files / "db.json").read_text())
    from_csv = json.loads((files / "csv.json").read_text())
    assert from_db["model"]["rmse"] == pytest.approx(from_csv["model"]["rmse"], rel=1e-9)
    assert from_db["nominal"]["rmse"] > 10 * from_db["model"]["rmse"]


def test_settings_from_the_environment_are_one_line(files):
    r = subprocess.run(
        [sys.executable, "-m", "robocal.server.cli", "serve", "--db", "s.db"],
        cwd=files,
        capture_output=True,
        text=True,
        timeout=120,
        env={**__import__("os").environ, "ROBOCAL_JOB_WORKERS": "lots"},
    )
    one_line_error(r, "ROBOCAL_JOB_WORKERS", "'lots'")


def test_every_option_and_argument_has_help():
    from robocal.server.cli import build_parser

    missing = []

    def walk(parser, where):
        for action in parser._actions:
            if isinstance(action, __import__("argparse")._SubParsersAction):
                for name, sub in action.choices.items():
                    walk(sub, f"{where} {name}")
            if not action.help:
                missing.append(f"{where} {'/'.join(action.option_strings) or action.dest}")

    walk(build_parser(), "robocal")
    assert not missing, "no help text: " + ", ".join(missing)


def test_a_campaign_not_done_is_used_with_a_note(files, tmp_path):
    """An e-stopped campaign's measured poses are calibrated on, and the user is told so."""
    import sqlite3

    # copied through SQLite (its backup), never by hand: a copy of the bare file misses the log
    with sqlite3.connect(files / "a.db") as a, sqlite3.connect(tmp_path / "stopped.db") as c:
        a.backup(c)
        c.execute("UPDATE campaign SET status = 'estopped' WHERE id = 1")
    a.close()
    c.close()
    r = robocal("calibrate", "stopped.db", "--campaign", 1, "--out", "m.json", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    (line,) = r.stderr.strip().splitlines()
    assert "note: stopped.db: campaign 1" in line and "estopped, not done" in line, line
    assert "30 of 30 poses" in line


OVERWRITES = [
    (("calibrate", "meas.csv", "--out", "meas.csv"), "meas.csv"),
    (("predict", "model.json", "meas.csv", "--out", "meas.csv"), "meas.csv"),
    (("simulate", "--cell", "cell.json", "--poses", 10, "--out", "cell.json"), "cell.json"),
    (("diagnose", "meas.csv", "--out", "r.json", "--model-out", "./r.json"), "r.json"),
    (("compensate", "model.json", "targets.csv", "--out", "targets.csv"), "targets.csv"),
    (("check", "model.json", "meas.csv", "--db", "h.db", "--out", "h.db"), "h.db"),
    (("export", "model.json", "--out", "model.json"), "model.json"),
]


@pytest.mark.parametrize("args,victim", OVERWRITES, ids=[a[0] for a, _ in OVERWRITES])
def test_an_output_that_is_an_input_is_refused_and_the_input_kept(files, tmp_path, args, victim):
    """`calibrate meas.csv --out meas.csv` replaced the campaign with the model ('model written
    to meas.csv'); predict, simulate, compensate, check and export alike, and diagnose's report
    with its model: refused in one line naming the flag and the file, nothing touched."""
    for name in ("meas.csv", "model.json", "targets.csv"):
        (tmp_path / name).write_bytes((files / name).read_bytes())
    (tmp_path / "cell.json").write_text('{"robot": "irb2600", "targets": {"A": [60, 0, 35]}}')
    (tmp_path / "h.db").write_bytes(b"")
    before = (tmp_path / victim).read_bytes() if (tmp_path / victim).exists() else None
    r = robocal(*args, cwd=tmp_path)
    one_line_error(r, victim, "overwritten")
    after = (tmp_path / victim).read_bytes() if (tmp_path / victim).exists() else None
    assert after == before
