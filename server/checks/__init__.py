"""Quick checks of a deployed model: the check, its plan, its run on the cell, its chart, the service's part."""
