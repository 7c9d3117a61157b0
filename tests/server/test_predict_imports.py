"""`robocal predict` starts with numpy alone (workflow.py's promise): no scipy, matplotlib or rich
in the modules its path imports, whatever module a refactor moves a function into."""

from __future__ import annotations

import subprocess
import sys

HEAVY = ("scipy", "matplotlib", "rich", "rerun")


def test_predict_path_imports_no_heavy_package():
    code = (
        "import sys\n"
        "from robocal.server.cli import predict\n"
        "from robocal.server.calibration import workflow\n"
        "from robocal.server.formats import campaign_csv\n"
        f"print(' '.join(m for m in {HEAVY!r} if m in sys.modules))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "", f"imported on predict's path: {out.stdout.strip()}"
