"""The application: file formats, the command line, benchmarks."""

import os

# Our matrices are small (tens of columns): threaded BLAS gains nothing on them, and its spinning
# threads slow them a hundredfold when the other core is busy. This runs before the command line
# imports numpy.
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")
