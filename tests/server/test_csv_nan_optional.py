"""'NaN' or 'inf' in an optional column (time_s, temp_c) is refused as in a required one (the
contract: NaN refused, naming file, line and column): numpy's column reader took 'NaN' in
temp_c as a blank, and the campaign calibrated."""

import pytest

from robocal.server.cli import main
from tests.real import rewritten


@pytest.mark.parametrize(("column", "value"), [("temp_c", "NaN"), ("time_s", "inf")])
def test_a_non_finite_optional_value_is_refused(tmp_path, capsys, column, value):
    meas, bad = tmp_path / "meas.csv", tmp_path / "bad.csv"
    assert main(["simulate", "--poses", "20", "--seed", "3", "--out", str(meas)]) == 0
    seen = []

    def spoiled(r: dict) -> dict:
        seen.append(r)
        return {**r, column: value} if len(seen) == 11 else r

    rewritten(meas, bad, spoiled)
    capsys.readouterr()
    args = ["calibrate", str(bad), "--method", "ls-sum", "--out", str(tmp_path / "m.json")]
    assert main(args) == 1
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"robocal: error: {bad}:12:") and f"column '{column}'" in err, err
    assert f"{value!r} is not a finite number" in err, err
