"""The compressed rows of a mesh's exact (tetrahedron, voxel) overlaps, recorded in
parallel: the tetrahedra in fixed chunks, each chunk into its own stretch of one buffer
sized by the expected cell count, then packed.

A tetrahedron's row is what :func:`ctseg._tet_clip._record` makes of it alone, so the
rows, and every sum over them, are the same whatever the chunking and the thread count.

Private: :class:`ctseg.tetra_gray.VoxelOverlaps` is the entry point.
"""
import numpy as np
from numba import njit, prange

from ._tet_clip import _record

_CHUNK_TETS = 2048
"""Tetrahedra per chunk: many chunks per thread even out their unequal costs; a few per
chunk would waste the buffers' slack."""


@njit(cache=True, parallel=True)
def _record_chunks(P, nz, ny, nx, bounds, offsets, caps, ends, voxel, overlap, done):
    """Chunk c (tetrahedra ``bounds[c]:bounds[c + 1]``) into ``voxel`` and ``overlap`` at
    ``offsets[c]``, at most ``caps[c]`` entries; ``ends[t]``: the count of its chunk's
    entries up to tetrahedron t included; ``done[c]``: :func:`_record`'s return (the
    chunk's length when it fitted)."""
    for c in prange(bounds.shape[0] - 1):
        t0 = bounds[c]
        t1 = bounds[c + 1]
        local = np.zeros(t1 - t0 + 1, np.int64)
        a = offsets[c]
        done[c] = _record(P[t0:t1], nz, ny, nx, 0, local, voxel[a:a + caps[c]],
                          overlap[a:a + caps[c]])
        for t in range(t0, t1):
            ends[t] = local[t - t0 + 1]


def _record_growing(P, dims, itype, cap):
    """One chunk alone, its buffers grown until it fits: (ends, voxel, overlap)."""
    m = len(P)
    start = np.zeros(m + 1, np.int64)
    voxel, overlap = np.empty(cap, itype), np.empty(cap)
    t = 0
    while True:
        t = _record(P, *dims, t, start, voxel, overlap)
        if t < 0:
            return t, None, None
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
    them, or ``(-1 - t, None, None)`` if tetrahedron t outgrew the kernel's buffers.
    """
    m = len(P)
    itype = np.int32 if int(np.prod(dims)) < 2 ** 31 else np.int64
    bounds = np.unique(np.r_[np.arange(0, m, _CHUNK_TETS), m]).astype(np.int64)
    cum = np.r_[0.0, np.cumsum(expected)]
    # the expected count fills the buffers nearly exactly: rarely a chunk done again
    caps = (1.02 * (cum[bounds[1:]] - cum[bounds[:-1]])).astype(np.int64) + 256
    offsets = np.r_[0, np.cumsum(caps)[:-1]].astype(np.int64)
    ends = np.zeros(m, np.int64)
    voxel, overlap = np.empty(int(caps.sum()), itype), np.empty(int(caps.sum()))
    done = np.zeros(len(bounds) - 1, np.int64)
    _record_chunks(P, *dims, bounds, offsets, caps, ends, voxel, overlap, done)
    pieces, start, q = [], np.zeros(m + 1, np.int64), 0
    for c, (t0, t1) in enumerate(zip(bounds[:-1], bounds[1:])):
        if done[c] < 0:  # tetrahedron t0 - 1 - done[c] outgrew the buffers
            return int(done[c]) - t0, None, None
        if done[c] == t1 - t0:
            n = int(ends[t1 - 1])
            pieces.append((voxel[offsets[c]:offsets[c] + n], overlap[offsets[c]:offsets[c] + n]))
            start[t0 + 1:t1 + 1] = q + ends[t0:t1]
        else:  # the chunk overflowed its stretch
            e, v, o = _record_growing(P[t0:t1], dims, itype, int(2 * caps[c]))
            if v is None:
                return int(e) - t0, None, None
            n = int(e[-1])
            pieces.append((v[:n], o[:n]))
            start[t0 + 1:t1 + 1] = q + e
        q += n
    if not pieces:
        return start, np.empty(0, itype), np.empty(0)
    return (start, np.concatenate([p[0] for p in pieces]),
            np.concatenate([p[1] for p in pieces]))
