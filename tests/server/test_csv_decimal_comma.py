"""A spreadsheet's European export (semicolons between fields, decimal commas) is said as such at
the header: it was 'row has 10 fields but the header has 1 (extra value '325100;17')' on line 2."""

from robocal.server.cli import main
from tests.real import REAL

IRB = REAL / "irb120_wu"


def test_semicolons_and_decimal_commas_are_named(tmp_path, capsys):
    lines = (IRB / "train.csv").read_text().splitlines()
    path = tmp_path / "excel.csv"
    path.write_text("\n".join(x.replace(",", ";").replace(".", ",") for x in lines) + "\n")
    args = [
        "calibrate",
        str(path),
        "--cell",
        str(IRB / "cell.json"),
        "--out",
        str(tmp_path / "m.json"),
    ]
    assert main(args) == 1
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"robocal: error: {path}:1: the header is one column"), err
    assert "separated by semicolons, expected commas" in err, err
    assert err.endswith("its rows' commas look like decimal commas: give decimal points"), err
