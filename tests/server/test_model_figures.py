"""A model file's fit block and its diagnosis's held-out figures read back: a negative or
non-finite error figure is refused at its field in one line, as the validation block's are."""

import json

import pytest

from robocal.server.cli import main as robocal
from robocal.server.formats.errors import InputError
from robocal.server.formats.model_json import read_model

FINAL = {"model": "geometric", "holdout_rmse_mm": 0.02, "holdout_max_mm": 0.05}


@pytest.fixture(scope="module")
def made(tmp_path_factory):
    d = tmp_path_factory.mktemp("figures")
    assert robocal(["simulate", "--poses", "20", "--seed", "3", "--out", str(d / "m.csv")]) == 0
    for method in ("ls-sum", "nominal"):
        out = d / f"{method}.json"
        assert robocal(["calibrate", str(d / "m.csv"), "--method", method, "--out", str(out)]) == 0
    return d


EDITS = [
    # (what the hand edit sets, the field named, why)
    (("fit", "rmse_mm"), -0.5, "fit.rmse_mm", "-0.5 is below the minimum 0"),
    (("fit", "rmse_phi_mm"), float("inf"), "fit.rmse_phi_mm", "not a finite number"),
    (("fit", "ap_max_mm"), float("nan"), "fit.ap_max_mm", "not a finite number"),
    (("fit", "F_mm2", "A"), -1e-3, "fit.F_mm2.A", "below the minimum 0"),
    (("fit", "condition_number"), -24.0, "fit.condition_number", "below the minimum 0"),
    (("fit", "seconds"), -1, "fit.seconds", "below the minimum 0"),
    (("diagnosis", "final", "holdout_rmse_mm"), -0.02, "diagnosis.final.holdout_rmse_mm", "min"),
    (("diagnosis", "final", "holdout_max_mm"), float("nan"), "diagnosis.final.holdout_max_mm", ""),
]


def _edited(made, keys, value):
    doc = json.loads((made / "ls-sum.json").read_text())
    doc["diagnosis"] = {"final": dict(FINAL)}  # as a diagnosis writes it
    block = doc
    for k in keys[:-1]:
        block = block[k]
    block[keys[-1]] = value
    path = made / f"{'_'.join(keys)}.json"
    path.write_text(json.dumps(doc, indent=2))
    return path


def test_the_files_as_written_are_read(made):
    """The program's own figures pass: a fit's, and the nominal method's NaN condition number
    (no fit: nothing to condition), and a diagnosis's final figures."""
    assert read_model(made / "ls-sum.json").fit.rmse_mm > 0
    assert read_model(made / "nominal.json").fit.condition_number != 0
    assert read_model(_edited(made, ("diagnosis", "final", "model"), "geometric")).diagnosis


@pytest.mark.parametrize("keys,value,field,why", EDITS, ids=[e[2] for e in EDITS])
def test_a_negative_or_non_finite_figure_is_refused_at_its_field(made, keys, value, field, why):
    path = _edited(made, keys, value)
    with pytest.raises(InputError) as e:
        read_model(path)
    said = str(e.value)
    print("\n", said)
    assert path.name in said and f"{field}:" in said and why in said, said
    assert "\n" not in said


def test_predict_says_it_in_one_line(made, capsys):
    path = _edited(made, ("fit", "rmse_mm"), -0.5)
    capsys.readouterr()
    code = robocal(["predict", str(path), str(made / "m.csv"), "--out", str(made / "p.csv")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code != 0 and len(err) == 1 and "fit.rmse_mm" in err[0], err
