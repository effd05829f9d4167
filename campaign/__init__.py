"""Campaign orchestration and command line.

BLAS runs on one thread unless the environment names a thread count (``OPENBLAS_NUM_THREADS``,
``OMP_NUM_THREADS`` or ``MKL_NUM_THREADS``): the numerics are many small and batched products (3x3 per pose,
300 x 2048 GP blocks), which threaded BLAS slows down, most of all on a shared machine (``reprocess`` of a
200 000-row CSV: 58 s on one thread, 128 s on two; ``python bench/bench_scale.py --threads 2``). Set here, before
any module of the package imports numpy.
"""
import os

_BLAS_THREADS = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")
if not any(name in os.environ for name in _BLAS_THREADS):
    for _name in _BLAS_THREADS:
        os.environ[_name] = "1"
