"""The real campaigns measured by others, in ../shared/data/real beside the repository."""

import json
from pathlib import Path

REAL = Path(__file__).resolve().parents[2] / "shared" / "data" / "real"
CAMPAIGNS = ("irb120_wu", "qkm_hl6")


def campaign_files(name: str) -> tuple[Path, Path]:
    """(train.csv, cell.json) of one real campaign."""
    return REAL / name / "train.csv", REAL / name / "cell.json"


def import_real(client, name: str, tolerance_mm: float | None = None) -> int:
    """A real campaign's cell (with the application's tolerance_mm when given) and train.csv
    uploaded through the API (an httpx client with the token); the imported campaign's id."""
    cell = json.loads((REAL / name / "cell.json").read_text())
    if tolerance_mm is not None:
        cell["tolerance_mm"] = tolerance_mm
    r = client.post("/api/cells", content=json.dumps(cell).encode())
    assert r.status_code == 201, r.text
    r = client.post(
        "/api/measurements/import",
        content=(REAL / name / "train.csv").read_bytes(),
        params={"filename": "train.csv", "cell_id": r.json()["id"]},
    )
    assert r.status_code == 201, r.text
    return r.json()["id"]


def rewritten(src: Path, dst: Path, change) -> None:
    """src's rows (a CSV with a header) each passed through change (a dict to a dict) into dst:
    a campaign mangled as a user's file may be."""
    import csv

    with open(src, newline="") as f:
        rows = list(csv.DictReader(f))
    with open(dst, "w", newline="") as f:
        w = csv.DictWriter(f, list(rows[0]))
        w.writeheader()
        w.writerows(change(r) for r in rows)
