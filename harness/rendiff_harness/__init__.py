"""rendiff's Python side: external renderer backends and the OpenImageIO comparison.

The Rust core resolves scenes and orchestrates runs; this package renders the
resolved scene with renderers that only have Python or CLI front ends, and
compares buffers with OpenImageIO + numpy.
"""

import os

BLAS_THREADS = "1"
"""numpy's OpenBLAS threads in a harness process, unless OPENBLAS_NUM_THREADS already says: set
here, before any module of the package imports numpy, since OpenBLAS reads it when it loads.
`rendiff check` runs a harness process per core (render workers, comparison workers), so a
second BLAS thread per process only busy-waits for work on a CPU another process needs; the
comparison's small SVDs and products gain nothing from it (the main job's comparison alone:
13.5 s with OpenBLAS's default of a thread per CPU, 11.8 s with one, a build beside it)."""

os.environ.setdefault("OPENBLAS_NUM_THREADS", BLAS_THREADS)
