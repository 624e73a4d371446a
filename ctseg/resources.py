"""Memory needed by a job, checked before the work starts: an input that cannot fit fails
at once with a clear message instead of being killed by the system hours later. And the
probes that measure what a job used: resident memory now, its peak since a reset, and the
peak while a block runs (:class:`PeakRss`, the 3D mode's per-stage peaks)."""

import os
import sys
import threading

from .errors import InputError

SLICE_BYTES_PER_PIXEL = 160
"""Peak resident memory of :func:`ctseg.segment_image` per pixel of the slice, with a 2x
margin: benchmarks/memory.py measured 79 and 70 bytes per pixel above the process's
starting memory at 2048^2 and 4096^2 (see the README's robustness section)."""

RESULT_BYTES_PER_VOXEL = 24
"""Memory that a volume's finished slice meshes hold, per voxel, with a 2x margin (13
measured on a 512^3 volume: 2.0 million triangles)."""

LEVEL_BYTES_PER_VOXEL = 48
"""Working memory per voxel of the slices that measure a volume's material levels."""

VOLUME_3D_BYTES_PER_VOXEL = 400
"""Peak resident memory of the 3D mode per voxel, with a margin of 2-2.5x:
benchmarks/volume3d.py measured 774 MiB for a 160^3 volume and 2560 MiB for 256^3, 198
and 160 bytes per voxel with the input and the interpreter
(benchmarks/results/volume3d_ctseg3d.md; 256 and 203 before the 3D mode kept its heap
and freed its density early). A 512^3 volume is refused below 50 GiB."""


SITE_3D_BYTES = 12 * 1024
"""Peak memory of the 3D mode per site beyond the default density (one per
``voxels_per_site`` voxels), with a 2x margin: 12000 -> 30000 sites on a 61 x 100 x 100 snow
volume raised the peak by 97 MiB, 5.6 KiB per site (tetrahedra, overlaps, blur pass)."""


def available_bytes():
    """Memory the system can still give (MemAvailable), or None where unknown."""
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return None


_PAGE_BYTES = os.sysconf("SC_PAGE_SIZE") if hasattr(os, "sysconf") else 4096


def _status_kib(field):
    """A field of /proc/self/status in KiB (VmHWM: the peak), None where there is none."""
    try:
        with open("/proc/self/status") as fh:
            for line in fh:
                if line.startswith(field + ":"):
                    return int(line.split()[1])
    except OSError:
        pass
    return None


def reset_peak_rss():
    """Start a new peak of this process's resident memory: VmHWM back to the current RSS
    (Linux >= 4.0, /proc/self/clear_refs). False where the system refuses; the peak is
    then the process's lifetime peak."""
    try:
        with open("/proc/self/clear_refs", "w") as fh:
            fh.write("5")
        return True
    except OSError:
        return False


def rss_mib():
    """This process's resident memory now, MiB (/proc/self/statm; NaN where unknown)."""
    try:
        with open("/proc/self/statm") as fh:
            return int(fh.read().split()[1]) * _PAGE_BYTES / 2 ** 20
    except OSError:
        return float("nan")


def peak_rss_mib():
    """This process's peak resident memory since :func:`reset_peak_rss` (its lifetime peak
    where that was refused), MiB; NaN where unknown. Counts every thread and every
    allocator (numpy, numba, Qhull), at no cost while the work runs."""
    kib = _status_kib("VmHWM")
    if kib is None:
        try:
            import resource
        except ImportError:  # Windows
            return float("nan")
        peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
        return peak / 2 ** 20 if sys.platform == "darwin" else peak / 1024  # bytes there
    return kib / 1024


class PeakRss:
    """The process's peak resident memory while a ``with`` block runs, MiB (``peak_mib``).

    Sampled every ``interval_s`` on a daemon thread and at both ends (Linux, /proc), so a
    spike shorter than the interval can be missed; the system's own peak counter (VmHWM)
    is left alone, so a measurement around this one stays right. Where there is no /proc,
    the process's lifetime peak (:func:`peak_rss_mib`) at the end.

    Example
    -------
    >>> with PeakRss() as probe:
    ...     data = bytearray(10 ** 6)
    >>> probe.peak_mib > 0
    True
    """

    def __init__(self, interval_s=0.01):
        self.interval_s = float(interval_s)
        self.peak_mib = float("nan")
        self._stop = threading.Event()
        self._thread = None

    def _sample(self):
        rss = rss_mib()
        if not rss <= self.peak_mib:  # also replaces the NaN (a NaN rss never does)
            self.peak_mib = rss

    def _run(self):
        while not self._stop.wait(self.interval_s):
            self._sample()

    def __enter__(self):
        self._sample()
        if self.peak_mib == self.peak_mib:  # /proc is there
            self._thread = threading.Thread(target=self._run, daemon=True)
            self._thread.start()
        return self

    def __exit__(self, *exc):
        if self._thread is not None:
            self._stop.set()
            self._thread.join()
            self._sample()
        else:
            self.peak_mib = peak_rss_mib()
        return False


def slice_bytes(rows, cols):
    """Estimated peak memory of segmenting one (rows, cols) slice."""
    return SLICE_BYTES_PER_PIXEL * int(rows) * int(cols)


def fits_in_memory(needed):
    """Whether ``needed`` bytes fit in what the system has available (True where unknown),
    and that amount (None where unknown)."""
    have = available_bytes()
    return have is None or needed <= have, have


def check_memory(needed, what, hint=""):
    """Raise InputError when ``needed`` bytes exceed what the system has available.

    Parameters
    ----------
    needed : int
        Estimated peak bytes.
    what : str
        What is being done, for the message.
    hint : str
        How to need less (e.g. fewer worker processes).
    """
    have = available_bytes()
    if have is not None and needed > have:
        raise InputError(f"{what} needs about {needed / 2 ** 30:.1f} GiB of memory and "
                         f"{have / 2 ** 30:.1f} GiB are available{'; ' + hint if hint else ''}")
