"""The harness's processes run one BLAS thread each (rendiff_harness.BLAS_THREADS)."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

_BLAS_THREADS_PROBE = """
import os
before = len(os.listdir("/proc/self/task"))
import rendiff_harness
import numpy as np
np.ones((64, 64)) @ np.ones((64, 64))
print(os.environ.get("OPENBLAS_NUM_THREADS"), len(os.listdir("/proc/self/task")) - before)
"""


@pytest.mark.parametrize(("given", "expected"), [(None, ["1", "0"]), ("2", ["2", "1"])])
def test_the_harness_runs_one_blas_thread_unless_told(given: str | None, expected: list[str]) -> None:
    """rendiff_harness.BLAS_THREADS reaches OpenBLAS when the package is imported before numpy
    (counted: the threads OpenBLAS starts when it loads); a user's own setting is kept."""
    env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_NUM_THREADS"}
    if given is not None:
        env["OPENBLAS_NUM_THREADS"] = given
    out = subprocess.run(
        [sys.executable, "-c", _BLAS_THREADS_PROBE], env=env, capture_output=True, text=True, check=True
    ).stdout.split()
    assert out == expected
