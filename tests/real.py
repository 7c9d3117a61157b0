"""The real campaigns measured by others, in ../shared/data/real beside the repository."""

from pathlib import Path

REAL = Path(__file__).resolve().parents[2] / "shared" / "data" / "real"
CAMPAIGNS = ("irb120_wu", "qkm_hl6")


def campaign_files(name: str) -> tuple[Path, Path]:
    """(train.csv, cell.json) of one real campaign."""
    return REAL / name / "train.csv", REAL / name / "cell.json"
