"""Test session set-up."""

import os

# As in the CLI: single-threaded BLAS, since two test workers share two cores.
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")
