"""The compressed rows of a mesh's exact (tetrahedron, voxel) overlaps, recorded in
parallel: the tetrahedra in fixed chunks, each chunk into its own stretch of one buffer
sized by the expected cell count (into buffers of its own, grown, where it overflows),
then packed in place.

A tetrahedron's row is what :func:`ctseg._tet_clip._record` makes of it alone, so the
rows, and every sum over them, are the same whatever the chunking and the thread count.

The chunks run on Python threads (the kernel releases the GIL), not in a numba ``prange``,
which on two threads took 1.14x as long for the same rows (benchmarks/overlap_rows.py).

Private: :class:`ctseg.tetra_gray.VoxelOverlaps` is the entry point.
"""
import numpy as np

from ._tet_clip import _record
from ._threads import thread_map

_CHUNK_TETS = 2048
"""Tetrahedra per chunk: many chunks per thread even out their unequal costs; a few per
chunk would waste the buffers' slack."""


def _record_growing(P, dims, itype, cap):
    """One chunk, its buffers grown until it fits: (ends, voxel, overlap), ``ends[t]``
    the count of the chunk's entries up to tetrahedron t included."""
    m = len(P)
    start = np.zeros(m + 1, np.int64)
    voxel, overlap = np.empty(cap, itype), np.empty(cap)
    t = 0
    while True:
        t = _record(P, *dims, t, start, voxel, overlap)
        if t == m:
            return start[1:], voxel, overlap
        cap = int(1.25 * cap) + 4096
        voxel, overlap = _grown(voxel, start[t], cap), _grown(overlap, start[t], cap)


def _grown(a, keep, size):
    out = np.empty(size, a.dtype)
    out[:keep] = a[:keep]
    return out


def overlap_rows(P, dims, expected):
    """Rows of the corners ``P`` (m, 4, 3, index units, inside the box of ``dims``).

    ``expected`` (m,): each tetrahedron's expected cell count (the buffers' sizes).
    Returns ``(start, voxel, overlap)`` as :class:`ctseg.tetra_gray.VoxelOverlaps` keeps
    them.
    """
    m = len(P)
    itype = np.int32 if int(np.prod(dims)) < 2 ** 31 else np.int64
    bounds = np.unique(np.r_[np.arange(0, m, _CHUNK_TETS), m]).astype(np.int64)
    cum = np.r_[0.0, np.cumsum(expected)]
    # the expected count fills the buffers nearly exactly: rarely a chunk grown
    caps = (1.02 * (cum[bounds[1:]] - cum[bounds[:-1]])).astype(np.int64) + 256
    offsets = np.r_[0, np.cumsum(caps)[:-1]].astype(np.int64)
    voxel, overlap = np.empty(int(caps.sum()), itype), np.empty(int(caps.sum()))

    def chunk(c):  # (ends, None, None) when written in place, else as _record_growing
        t0, t1, a, k = bounds[c], bounds[c + 1], offsets[c], caps[c]
        start = np.zeros(t1 - t0 + 1, np.int64)
        t = _record(P[t0:t1], *dims, 0, start, voxel[a:a + k], overlap[a:a + k])
        if t == t1 - t0:
            return start[1:], None, None
        return _record_growing(P[t0:t1], dims, itype, int(2 * k))

    done = thread_map(chunk, range(len(caps)))
    pieces, start, q = [], np.zeros(m + 1, np.int64), 0
    for c, (e, v, o) in enumerate(done):
        n = int(e[-1])
        a = offsets[c]
        pieces.append((voxel[a:a + n], overlap[a:a + n]) if v is None else (v[:n], o[:n]))
        start[bounds[c] + 1:bounds[c + 1] + 1] = q + e
        q += n
    if all(v is None for _, v, _ in done):  # packed in place: no second copy of the rows
        for (pv, po), a in zip(pieces, np.r_[0, np.cumsum([len(pv) for pv, _ in pieces])]):
            voxel[a:a + len(pv)] = pv
            overlap[a:a + len(po)] = po
        return start, voxel[:q], overlap[:q]
    return (start, np.concatenate([p[0] for p in pieces]),
            np.concatenate([p[1] for p in pieces]))
