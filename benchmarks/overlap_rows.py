"""The exact tetrahedron/voxel overlaps of a 3D mesh: the chunked recorder on Python threads
(:func:`ctseg._overlap_rows.overlap_rows`, what the 3D mode runs) against the same kernel
in a numba ``prange`` over the chunks (the recorder before it), against one serial pass,
and against one serial pass of the kernel before the face integrals (the polyhedron sweep
of benchmarks/_r3d_clip.py), side by side in this process.

    python benchmarks/overlap_rows.py [--size 160] [--repeats 3]
                                      [--out benchmarks/results/overlap_rows.md]

The mesh is the 3D mode's tetrahedra of :func:`ctseg.phantoms3d.make_part_3d` (seed 0) on
its CVT sites after the coarse Lloyd and 2 fine iterations (the default count and sizes of
elements, made in seconds). Every
variant must give the serial pass's rows bit for bit (the polyhedron sweep: the same
per-tetrahedron and per-voxel sums to 1e-12); the times are medians of repeats,
interleaved, with numba's thread count set per row.
"""
import argparse
import os
import platform
import time

import numba
import numpy as np
from _r3d_clip import _record as _record_r3d  # benchmarks/ is this script's folder
from accuracy import write_results
from numba import njit, prange

from ctseg import stages3d
from ctseg._overlap_rows import overlap_rows
from ctseg._tet_clip import _record
from ctseg.phantoms3d import make_part_3d
from ctseg.params import resolve
from ctseg.tetra_gray import _corners, _expected_cells


@njit(cache=False, parallel=True)
def _prange_chunks(P, nz, ny, nx, bounds, offsets, caps, ends, voxel, overlap, done):
    # the recorder before the thread pool: the chunks in a prange, each into its stretch
    for c in prange(bounds.shape[0] - 1):
        t0 = bounds[c]
        t1 = bounds[c + 1]
        local = np.zeros(t1 - t0 + 1, np.int64)
        a = offsets[c]
        done[c] = _record(P[t0:t1], nz, ny, nx, 0, local, voxel[a:a + caps[c]],
                          overlap[a:a + caps[c]])
        for t in range(t0, t1):
            ends[t] = local[t - t0 + 1]


def prange_rows(P, dims, expected, chunk=2048):
    m = len(P)
    bounds = np.unique(np.r_[np.arange(0, m, chunk), m]).astype(np.int64)
    cum = np.r_[0.0, np.cumsum(expected)]
    caps = (1.02 * (cum[bounds[1:]] - cum[bounds[:-1]])).astype(np.int64) + 256
    offsets = np.r_[0, np.cumsum(caps)[:-1]].astype(np.int64)
    ends = np.zeros(m, np.int64)
    voxel, overlap = np.empty(int(caps.sum()), np.int32), np.empty(int(caps.sum()))
    done = np.zeros(len(bounds) - 1, np.int64)
    _prange_chunks(P, *dims, bounds, offsets, caps, ends, voxel, overlap, done)
    if not np.array_equal(done, np.diff(bounds)):
        raise RuntimeError("a chunk overflowed its stretch: not timed")
    pieces, start, q = [], np.zeros(m + 1, np.int64), 0
    for c, (t0, t1) in enumerate(zip(bounds[:-1], bounds[1:])):
        n = int(ends[t1 - 1])
        pieces.append((voxel[offsets[c]:offsets[c] + n], overlap[offsets[c]:offsets[c] + n]))
        start[t0 + 1:t1 + 1] = q + ends[t0:t1]
        q += n
    return start, np.concatenate([p[0] for p in pieces]), np.concatenate([p[1] for p in pieces])


def serial_rows(P, dims, expected, record=_record):
    start = np.zeros(len(P) + 1, np.int64)
    cap = int(1.05 * expected.sum()) + 4096
    voxel, overlap = np.empty(cap, np.int32), np.empty(cap)
    if record(P, *dims, 0, start, voxel, overlap) != len(P):
        raise RuntimeError("the serial buffers were too small")
    return start, voxel[:start[-1]], overlap[:start[-1]]


def r3d_rows(P, dims, expected):
    return serial_rows(P, dims, expected, _record_r3d)


def same_sums(got, ref, n_voxels):
    """The per-tetrahedron and per-voxel sums of two sets of rows agree to 1e-12."""
    sums = []
    for start, voxel, overlap in (got, ref):
        tet = np.repeat(np.arange(len(start) - 1), np.diff(start))
        sums.append((np.bincount(tet, overlap, len(start) - 1),
                     np.bincount(voxel, overlap, n_voxels)))
    return all(np.allclose(a, b, rtol=1e-12, atol=1e-12) for a, b in zip(*sums))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--size", type=int, default=160)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--out", default=None, help="markdown path; the JSON goes beside it")
    args = ap.parse_args()
    image = make_part_3d(args.size, seed=0, keep_fractions=False).image.astype(np.float64)
    rho = stages3d.density_3d(image)
    params = resolve(fine_iter_3d=2)
    cvt = stages3d.cvt_sites_3d(rho, params, n_sites=stages3d.n_sites_3d(image)[0])
    mesh, _ = stages3d.tetrahedra_3d(cvt.sites, image.shape)
    P = _corners(mesh.points, mesh.tetrahedra, image.shape, (1.0, 1.0, 1.0))
    expected = _expected_cells(P)
    n_cores = numba.config.NUMBA_NUM_THREADS
    variants = [("serial pass", 1, serial_rows),
                ("serial pass, polyhedron sweep (the kernel before)", 1, r3d_rows)]
    for n in sorted({1, n_cores}):
        variants += [(f"prange chunks, {n} thread(s)", n, prange_rows),
                     (f"thread pool (ctseg), {n} thread(s)", n, overlap_rows)]
    ref = serial_rows(P, image.shape, expected)
    rows = [{"variant": name, "threads": n, "times_s": []} for name, n, _ in variants]
    for name, n, fn in variants:  # compile, and check every variant's rows once
        numba.set_num_threads(n)
        got = fn(P, image.shape, expected)
        if fn is r3d_rows:
            if not same_sums(got, ref, int(np.prod(image.shape))):
                raise RuntimeError(f"{name}: sums differ from the serial pass")
        elif not all(np.array_equal(a, b) for a, b in zip(got, ref)):
            raise RuntimeError(f"{name}: rows differ from the serial pass")
    for _ in range(args.repeats):
        for row, (name, n, fn) in zip(rows, variants):
            numba.set_num_threads(n)
            t = time.perf_counter()
            fn(P, image.shape, expected)
            row["times_s"].append(time.perf_counter() - t)
    base = float(np.median(rows[0]["times_s"]))
    lines = ["# Exact tetrahedron/voxel overlaps (benchmarks/overlap_rows.py)\n",
             f"{time.strftime('%Y-%m-%d')}, {os.cpu_count()} cores, {platform.machine()}; "
             f"make_part_3d({args.size}, seed 0), {len(P)} tetrahedra (coarse CVT sites), "
             f"{int(ref[0][-1])} overlaps; median of {args.repeats}, every variant's rows "
             "equal to the serial pass's bit for bit, the polyhedron sweep's sums to "
             "1e-12.\n",
             "| variant | threads | time s (median) | ratio to the serial pass |",
             "|---|---|---|---|"]
    for row in rows:
        med = float(np.median(row["times_s"]))
        row["median_s"], row["ratio"] = med, med / base
        lines.append(f"| {row['variant']} | {row['threads']} | {med:.2f} | {med / base:.2f} |")
    md = "\n".join(lines)
    print(md)
    if args.out:
        write_results(args.out, md, {"size": args.size, "tetrahedra": len(P), "rows": rows})


if __name__ == "__main__":
    main()
