"""An uploaded meas.csv read in a worker process: its parse runs in C for up to a second at a time
holding the GIL, which in the service would hold up every thread, the e-stop's too."""

from __future__ import annotations

import tempfile
from pathlib import Path

from robocal.server.compensate.model_files import _named, _upload
from robocal.server.formats.campaign_csv import read_campaign


def read_measurements(data: bytes, filename: str, robot, targets=None, report=None):
    """The campaign an uploaded meas.csv holds (Measurements), its SMRs among `targets` when
    given; InputError names the upload's line."""
    shown = Path(filename).name or "meas.csv"  # only a label: never a path on this machine
    with tempfile.TemporaryDirectory(prefix="robocal-import-") as tmp:
        path = _upload(Path(tmp), shown, data)
        with _named({str(path): shown}):
            return read_campaign(path, robot, targets)


def read_check(model_path, data: bytes, filename: str, report=None):
    """An uploaded check.csv read against a stored model (check.Prepared); InputError and
    DataError name the upload, never this machine's paths."""
    from robocal.server.calibration.workflow import DataError
    from robocal.server.checks.check import MAX_POSES, prepare

    shown = Path(filename).name or "check.csv"
    with tempfile.TemporaryDirectory(prefix="robocal-check-") as tmp:
        path = _upload(Path(tmp), shown, data)
        try:
            with _named({str(path): shown}):
                p = prepare(model_path, path)
        except DataError as e:
            raise DataError(str(e).replace(str(path), shown)) from None
    poses = len(p.readings.q)
    if poses > MAX_POSES:
        raise DataError(
            f"{shown}: {poses} poses; a quick check measures a few fixed poses (at most "
            f"{MAX_POSES}): calibrate with a campaign this large instead"
        )
    return p
