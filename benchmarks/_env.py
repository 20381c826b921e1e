"""The process environment of the timing scripts, imported first by each (before numpy,
OpenCV, MuJoCo or the rest of cablesim load): one BLAS/OpenMP thread and one OpenCV thread
per process (unless the caller set the variables), and the headless GL back end chosen
(:mod:`cablesim.gl`) before MuJoCo reads it.  The software renderer's threads
(``LP_NUM_THREADS``) are each script's choice, set before it renders."""

import os


def _configure() -> None:
    for name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(name, "1")
    import cv2  # after the variables above, which it reads when it loads

    import cablesim  # noqa: F401  (selects the headless GL back end)

    cv2.setNumThreads(1)


_configure()
