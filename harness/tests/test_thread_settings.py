"""Thread settings the harness makes for libraries it loads: one OpenBLAS thread per harness
process (rendiff_harness.BLAS_THREADS) and one OpenMP thread for FLIP (radiance.FLIP_THREADS),
each unless the user set the variable. Counted in a fresh process: the threads a library starts
when it loads or first runs, beside the calling thread."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

_BLAS_PROBE = """
import os
before = len(os.listdir("/proc/self/task"))
import rendiff_harness
import numpy as np
np.ones((64, 64)) @ np.ones((64, 64))
print(os.environ.get("OPENBLAS_NUM_THREADS"), len(os.listdir("/proc/self/task")) - before)
"""

_FLIP_PROBE = """
import os
import numpy as np
from rendiff_harness.judge import radiance
a = np.full((64, 64, 3), 0.5, dtype=np.float32)
before = len(os.listdir("/proc/self/task"))
radiance.flip_mean(a, a * 1.5)
print(os.environ.get("OMP_NUM_THREADS"), len(os.listdir("/proc/self/task")) - before)
"""


def _probe(code: str, variable: str, given: str | None) -> list[str]:
    """`code`'s output in a fresh Python with `variable` unset, or set to `given`."""
    env = {k: v for k, v in os.environ.items() if k != variable}
    if given is not None:
        env[variable] = given
    run = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
    return run.stdout.split()


# OpenBLAS caps its threads at the CPUs, so a second one needs a second CPU to show.
@pytest.mark.skipif((os.cpu_count() or 1) < 2, reason="one CPU: OpenBLAS starts no second thread anyway")
@pytest.mark.parametrize(("given", "expected"), [(None, ["1", "0"]), ("2", ["2", "1"])])
def test_the_harness_runs_one_blas_thread_unless_told(given: str | None, expected: list[str]) -> None:
    """BLAS_THREADS reaches OpenBLAS when the package is imported before numpy."""
    assert _probe(_BLAS_PROBE, "OPENBLAS_NUM_THREADS", given) == expected


@pytest.mark.parametrize(("given", "expected"), [(None, ["1", "0"]), ("3", ["3", "2"])])
def test_flip_runs_one_openmp_thread_unless_told(given: str | None, expected: list[str]) -> None:
    """FLIP_THREADS reaches libgomp only if set before flip-evaluator loads it."""
    pytest.importorskip("flip_evaluator")
    assert _probe(_FLIP_PROBE, "OMP_NUM_THREADS", given) == expected
