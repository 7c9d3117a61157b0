"""Pure numerics of robot calibration: arrays in, arrays out."""

import os

# Our matrices have tens of columns: threaded BLAS gains nothing on them, and its spinning threads
# slow them a hundredfold whenever another process keeps the other core busy. A BLAS loaded later
# (scipy's own) reads the variables when it loads; one loaded already (numpy's) is limited here.
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy  # noqa: E402, F401 - loads numpy's BLAS so that the limit below reaches it
from threadpoolctl import threadpool_limits  # noqa: E402

threadpool_limits(limits=1, user_api="blas")
