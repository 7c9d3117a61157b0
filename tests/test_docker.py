"""The container files stay in step with the repository (no Docker engine runs here to build them)."""

from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_dockerfile_copies_existing_paths():
    for line in (ROOT / "docker" / "Dockerfile").read_text().splitlines():
        if line.startswith("COPY "):
            for src in line.split()[1:-1]:
                assert (ROOT / src).exists(), f"Dockerfile copies missing {src}"


def test_compose_publishes_on_loopback_with_a_data_volume():
    text = (ROOT / "docker" / "compose.yaml").read_text()
    assert '"127.0.0.1:8000:8000"' in text
    assert "robocal-data:/data" in text
