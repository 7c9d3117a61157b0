"""robocal: a calibration workstation for industrial robot arms measured with a laser tracker."""

import os as _os

# The wheel ships solver, drivers, server, web and migrations inside this package; a checkout
# keeps them at the top level (the design card's layout), so the package reaches up for them.
_here = _os.path.dirname(_os.path.abspath(__file__))
if not _os.path.isdir(_os.path.join(_here, "server")):
    __path__.append(_os.path.dirname(_here))  # noqa: F821 (a package's own __path__)
