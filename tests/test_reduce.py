"""Long sums give the same bits whatever the BLAS's thread count (ctseg._reduce)."""
import os
import subprocess
import sys

import numpy as np

from ctseg._reduce import dot, weighted_variance

CHILD = """
import numpy as np
from ctseg._reduce import dot, weighted_variance
from ctseg.streak_basis import fit_streak_weight
rng = np.random.default_rng(0)
u, v, w = rng.normal(size=(3, 1_000_003))
img = rng.normal(size=(1000, 1001)); basis = rng.normal(size=(1000, 1001))
classes = (img > 0).astype(int); mask = np.abs(basis) < 2
print(dot(u, v).hex(), weighted_variance(u, np.abs(w)).hex(),
      *[float(x).hex() for x in fit_streak_weight(img, basis, classes, mask)])
"""


def test_same_bits_with_one_or_two_blas_threads():
    """OpenBLAS splits a long ddot over its threads (np.dot's last bits then follow the
    thread count); ours do not call it."""
    out = []
    for threads in ("1", "2"):
        env = dict(os.environ, OPENBLAS_NUM_THREADS=threads, OMP_NUM_THREADS=threads)
        out.append(subprocess.run([sys.executable, "-c", CHILD], env=env, check=True,
                                  capture_output=True, text=True).stdout)
    assert out[0] == out[1] and out[0].strip()


def test_equal_to_numpys_blas_results():
    rng = np.random.default_rng(1)
    u, v, w = rng.normal(size=(3, 50_001))
    assert abs(dot(u, v) - float(u @ v)) <= 1e-12 * float(np.abs(u) @ np.abs(v))
    np.testing.assert_allclose(weighted_variance(u, np.abs(w)), np.cov(u, aweights=np.abs(w)),
                               rtol=1e-12)
    np.testing.assert_allclose(weighted_variance([1.0, 3.0], [1.0, 1.0]), 2.0, rtol=1e-15)
