"""Regenerate the shipped sample volume and its ground truth (deterministic).

    python sample_data/make_sample_volume.py

Writes part_volume.nrrd (float32, linear attenuation in 1/cm, 40 x 80 x 80 voxels of
0.5 mm, origin 0) and part_volume_truth.npy (uint8 labels in the same (z, y, x) order:
0 air, 1 polymer, 2 aluminium, 3 steel) next to this file. The simulation is
ctseg.phantoms.make_volume with simulate=True: each slice of a multi-material part
(aluminium housing with a bore and pores, polymer bushing, steel shaft and bolt, shapes
varying smoothly from slice to slice) painted at 2x resolution, forward-projected with
a polychromatic spectrum (beam hardening, streaks next to the steel), Poisson noise at
1e6 photons per detector bin, and reconstructed by filtered back-projection.
"""
import os

import nrrd
import numpy as np

from ctseg.phantoms import make_volume

SEED = 2026
VOXEL_MM = 40.0 / 80  # make_volume simulates a 40 mm field of view

if __name__ == "__main__":
    here = os.path.dirname(os.path.abspath(__file__))
    p = make_volume(40, 80, seed=SEED, simulate=True)
    header = {"space": "left-posterior-superior", "space origin": np.zeros(3),
              "space directions": np.diag([VOXEL_MM] * 3), "kinds": ["domain"] * 3,
              "encoding": "raw"}
    nrrd.write(os.path.join(here, "part_volume.nrrd"), p.image.astype(np.float32), header,
               index_order="C")
    np.save(os.path.join(here, "part_volume_truth.npy"), p.truth.astype(np.uint8))
    for k, name in enumerate(p.names):
        m = p.truth == k
        print(f"{k} {name:10s} {m.sum():7d} voxels  median {np.median(p.image[m]):7.3f} 1/cm")
