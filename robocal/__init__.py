"""robocal: a calibration workstation for industrial robot arms measured with a laser tracker."""

import os as _os

# robocal/ holds links to the top-level folders (the design card's layout), so that a checkout
# and the wheel import alike and static tools resolve every robocal.* import. A checkout made
# without links (git's core.symlinks off) reaches up for the folders instead.
_here = _os.path.dirname(_os.path.abspath(__file__))
if not _os.path.isdir(_os.path.join(_here, "server")):
    __path__.append(_os.path.dirname(_here))  # noqa: F821 (a package's own __path__)
