"""The memory probes behind the per-stage peaks of the 3D mode's diagnostics."""
import numpy as np
import pytest

from ctseg.pipeline import stage_runner
from ctseg.resources import peak_rss_mib, reset_peak_rss, rss_mib


def test_a_stage_peak_sees_memory_freed_before_the_stage_ends():
    if not reset_peak_rss():
        pytest.skip("the system does not restart the resident-memory peak")
    times, peaks = {}, {}
    timed = stage_runner(lambda frac, name: None, times, peaks)

    def spike(n_bytes):
        a = np.ones(n_bytes // 8)  # written, so resident
        return float(a[::4096].sum())

    before = rss_mib()
    timed("big", 0.0, spike, 200 * 2 ** 20)
    timed("small", 0.5, spike, 8 * 2 ** 20)
    assert rss_mib() < before + 100  # the 200 MiB are gone again
    assert peaks["big"] >= before + 190
    assert peaks["small"] < peaks["big"] - 150  # the peak restarts with each stage
    assert set(times) == {"big", "small"}


def test_the_peak_is_never_below_the_memory_now():
    reset_peak_rss()
    assert peak_rss_mib() >= rss_mib() > 0
