"""Peak resident memory (and wall time) of the whole job on large inputs, each run in a
fresh process so that one run's peak does not hide in another's.

    python benchmarks/memory.py [--slices 512 1024 2048 4096] [--volume 64x512] [--jobs 2]

A slice of N x N is the sample slice's part, simulated at that size (fast variant of
:func:`ctseg.phantoms.make_volume`'s mixing, one slice); a volume ``SxN`` is S slices of
N x N as uint16. Default sites (one per 128 pixels). Writes benchmarks/results/memory.json.
"""
import argparse
import json
import os
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))

CHILD = r"""
import json, resource, sys, time
import numpy as np
from ctseg.phantoms import make_volume
kind, n, s, jobs = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4])
vol = make_volume(s if kind == "volume" else 1, n, seed=0, supersample=1)
data = (vol.image * 10000).astype(np.uint16) if kind == "volume" else vol.image[0]
base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
t0 = time.perf_counter()
if kind == "volume":
    from ctseg.volume import segment_volume
    res = segment_volume(data, mode="slices", n_jobs=jobs)
    n_tri = res.diagnostics["n_triangles"]
else:
    import ctseg
    res = ctseg.segment_image(data)
    n_tri = len(res.triangles)
wall = time.perf_counter() - t0
peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
kids = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
print(json.dumps({"wall_s": wall, "peak_mib": peak / 1024, "before_mib": base / 1024,
                  "worker_peak_mib": kids / 1024, "n_triangles": n_tri}))
"""


def measure(kind, n, slices=1, jobs=1):
    out = subprocess.run([sys.executable, "-c", CHILD, kind, str(n), str(slices), str(jobs)],
                         capture_output=True, text=True)
    if out.returncode:
        return {"error": out.stderr.strip().splitlines()[-1:]}
    return json.loads(out.stdout.strip().splitlines()[-1])


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--slices", type=int, nargs="*", default=[512, 1024, 2048])
    ap.add_argument("--volume", default=None, help="SLICESxSIZE, e.g. 512x512")
    ap.add_argument("--jobs", type=int, default=2)
    args = ap.parse_args()
    rows = []
    for n in args.slices:
        r = measure("slice", n)
        rows.append({"input": f"slice {n} x {n}", "pixels": n * n, **r})
        print(rows[-1], flush=True)
    if args.volume:
        s, n = (int(v) for v in args.volume.lower().split("x"))
        r = measure("volume", n, s, args.jobs)
        rows.append({"input": f"volume {s} x {n} x {n} uint16, {args.jobs} processes",
                     "pixels": s * n * n, **r})
        print(rows[-1], flush=True)
    print("| input | wall s | peak MiB (main) | peak MiB (largest worker) | bytes per pixel |")
    print("|---|---|---|---|---|")
    for r in rows:
        if "error" in r:
            print(f"| {r['input']} | failed: {r['error']} | | | |")
            continue
        per_px = r["peak_mib"] * 2 ** 20 / (r["pixels"] if "slice" in r["input"] else r["pixels"])
        print(f"| {r['input']} | {r['wall_s']:.1f} | {r['peak_mib']:.0f} | "
              f"{r['worker_peak_mib']:.0f} | {per_px:.0f} |")
    os.makedirs(os.path.join(HERE, "results"), exist_ok=True)
    with open(os.path.join(HERE, "results", "memory.json"), "w") as fh:
        json.dump({"when": time.strftime("%Y-%m-%d"), "cpu_count": os.cpu_count(), "rows": rows},
                  fh, indent=2)


if __name__ == "__main__":
    main()
