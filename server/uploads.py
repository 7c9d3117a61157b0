"""An uploaded meas.csv read in a worker process: its parse runs in C for up to a second at a time
holding the GIL, which in the service would hold up every thread, the e-stop's too."""

from __future__ import annotations

import tempfile
from pathlib import Path

from .formats.campaign_csv import read_campaign
from .model_files import _named, _upload


def read_measurements(data: bytes, filename: str, robot, report=None):
    """The campaign an uploaded meas.csv holds (Measurements); InputError names the upload's
    line."""
    shown = Path(filename).name or "meas.csv"  # only a label: never a path on this machine
    with tempfile.TemporaryDirectory(prefix="robocal-import-") as tmp:
        path = _upload(Path(tmp), shown, data)
        with _named({str(path): shown}):
            return read_campaign(path, robot)
