"""The memory probes behind the per-stage peaks of the 3D mode's diagnostics."""
import time

import numpy as np
import pytest

from ctseg.pipeline import stage_runner
from ctseg.resources import peak_rss_mib, reset_peak_rss, rss_mib


def spike(n_bytes, hold_s=0.1):
    """Hold ``n_bytes`` of written (resident) memory for ``hold_s``, then free it."""
    a = np.ones(n_bytes // 8)
    time.sleep(hold_s)
    return float(a[::4096].sum())


def test_a_stage_peak_sees_memory_freed_before_the_stage_ends():
    if not np.isfinite(rss_mib()):
        pytest.skip("no /proc: the stage peaks are the process's lifetime peak")
    times, peaks = {}, {}
    timed = stage_runner(lambda frac, name: None, times, peaks)
    before = rss_mib()
    timed("big", 0.0, spike, 200 * 2 ** 20)
    timed("small", 0.5, spike, 8 * 2 ** 20)
    assert rss_mib() < before + 100  # the 200 MiB are gone again
    assert peaks["big"] >= before + 190
    assert peaks["small"] < peaks["big"] - 150  # each stage has its own peak
    assert set(times) == {"big", "small"}


def test_the_stage_peaks_leave_the_process_peak_alone():
    """A benchmark around a run reads the system's peak counter: the stages must not
    restart it."""
    if not reset_peak_rss():
        pytest.skip("the system does not restart the resident-memory peak")
    spike(150 * 2 ** 20, 0.0)
    timed = stage_runner(lambda frac, name: None, {}, {})
    timed("after", 0.0, spike, 8 * 2 ** 20)
    assert peak_rss_mib() >= rss_mib() + 140


def test_the_peak_is_never_below_the_memory_now():
    reset_peak_rss()
    assert peak_rss_mib() >= rss_mib() > 0
