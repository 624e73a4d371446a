"""Fingerprints of the default outputs, to show a refactor changed nothing.

    python benchmarks/identity.py OUT.json        # record
    python benchmarks/identity.py OUT.json --compare BEFORE.json

Records, at default parameters, the SHA-1 of the points, triangles and materials of: the
shipped sample slice, ten simulated slices (256 x 256, seeds 0-9, four material sets) and
one simulated volume (16 x 96 x 96, slice by slice). ``--compare`` lists every case whose
bytes differ from an earlier record, with the share of elements whose material changed.
"""
import argparse
import hashlib
import json
import os
import sys

import numpy as np

import ctseg
from ctseg.phantoms import MATERIALS, make_phantom, make_volume

HERE = os.path.dirname(os.path.abspath(__file__))
SETS = [MATERIALS, ("air", "aluminium", "steel"), ("air", "polymer", "aluminium"),
        ("air", "aluminium")]


def _sha(a):
    return hashlib.sha1(np.ascontiguousarray(a).tobytes()).hexdigest()


def _record(seg):
    return {"points": _sha(seg.points), "triangles": _sha(seg.triangles),
            "material": _sha(seg.material), "n_triangles": int(len(seg.triangles)),
            "material_list": [int(v) for v in seg.material]}


def cases():
    sample = np.load(os.path.join(HERE, "..", "sample_data", "part_slice.npy"))
    yield "sample", lambda: ctseg.segment_image(sample)
    for seed in range(10):
        mats = SETS[seed % len(SETS)]
        p = make_phantom(256, seed=seed, materials=mats)
        yield f"slice seed {seed}", lambda p=p: ctseg.segment_image(p.image)


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("out")
    ap.add_argument("--compare")
    args = ap.parse_args(argv)
    from ctseg.volume import segment_volume

    rec = {}
    for name, run in cases():
        rec[name] = _record(run())
        print(name, rec[name]["n_triangles"], flush=True)
    vol = make_volume(16, 96, seed=3)
    vseg = segment_volume(vol.image, mode="slices")
    for k, s in enumerate(vseg.slices):
        rec[f"volume slice {k}"] = _record(s)
    with open(args.out, "w") as fh:
        json.dump(rec, fh)
    if args.compare:
        with open(args.compare) as fh:
            old = json.load(fh)
        bad = 0
        for name in old:
            a, b = old[name], rec.get(name)
            if b is None or any(a[k] != b[k] for k in ("points", "triangles", "material")):
                bad += 1
                if b and len(a["material_list"]) == len(b["material_list"]):
                    share = np.mean(np.array(a["material_list"]) != np.array(b["material_list"]))
                    print(f"DIFFERS {name}: materials changed on {share:.4%} of triangles")
                else:
                    print(f"DIFFERS {name}: another mesh")
        print(f"{len(old) - bad} of {len(old)} cases bit-identical")
        return 1 if bad else 0
    return 0


if __name__ == "__main__":
    sys.exit(main())
