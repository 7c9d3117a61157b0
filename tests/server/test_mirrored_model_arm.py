"""evaluate and check refuse mirrored readings naming the arm they registered: the model's
calibrated one ('the nominal arm ... fits the mirror image within 0.249 mm' was the model's),
while calibrate still names the nominal arm."""

from robocal.server.cli import main
from tests.real import REAL, rewritten

IRB = REAL / "irb120_wu"


def test_evaluate_and_check_name_the_models_arm(tmp_path, capsys):
    model, swapped = tmp_path / "model.json", tmp_path / "swapped.csv"
    rewritten(IRB / "train.csv", swapped, lambda r: {**r, "x": r["y"], "y": r["x"]})
    cal = ["calibrate", str(IRB / "train.csv"), "--cell", str(IRB / "cell.json")]
    assert main([*cal, "--method", "ls-sum", "--out", str(model)]) == 0
    capsys.readouterr()
    db = str(tmp_path / "checks.db")
    for args in (["evaluate", str(model), str(swapped)], ["check", str(model), str(swapped)]):
        assert main([*args, *(["--db", db] if args[0] == "check" else [])]) == 1
        err = capsys.readouterr().err.strip()
        print(err)
        assert err.startswith(f"robocal: error: {swapped}: the model's calibrated arm at the ")
        assert "look mirrored" in err and "nominal arm" not in err
    cal = ["calibrate", str(swapped), "--cell", str(IRB / "cell.json"), "--method", "ls-sum"]
    assert main(cal) == 1
    assert f"{swapped}: the nominal arm at the measured joints" in capsys.readouterr().err
