"""`python -m robocal.server.cli`."""

import sys

from . import main

sys.exit(main())
