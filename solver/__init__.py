"""Pure numerics of robot calibration: arrays in, arrays out."""

from threadpoolctl import threadpool_limits

# Our matrices have tens of columns: threaded BLAS gains nothing on them, and its spinning threads
# slow them a hundredfold whenever another process keeps the other core busy.
threadpool_limits(limits=1, user_api="blas")
