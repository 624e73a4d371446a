"""Regenerate the shipped sample slice and its ground truth (deterministic).

    python sample_data/make_sample.py

Writes part_slice.npy (float32, linear attenuation in 1/cm, 512 x 512, 80 um pixels) and
part_slice_truth.npy (uint8 labels: 0 air, 1 polymer, 2 aluminium, 3 steel) next to this
file. The simulation is ctseg.phantoms: a multi-material part (aluminium housing with
bore, bolt holes, thin fins and gas pores; polymer bushing and cover plate; steel shaft and
bolt) painted at 4x resolution, forward-projected in parallel beam over 512 angles with a
160 kV / 2 mm Cu polychromatic spectrum (beam hardening, photon starvation behind steel),
Poisson noise at 1e6 photons per detector bin, detector blur, and reconstructed by
filtered back-projection (Shepp-Logan filter).
"""
import os

import numpy as np

from ctseg.phantoms import make_phantom

SEED = 2026

if __name__ == "__main__":
    here = os.path.dirname(os.path.abspath(__file__))
    p = make_phantom(512, seed=SEED)
    np.save(os.path.join(here, "part_slice.npy"), p.image.astype(np.float32))
    np.save(os.path.join(here, "part_slice_truth.npy"), p.truth.astype(np.uint8))
    for k, name in enumerate(p.names):
        m = p.truth == k
        print(f"{k} {name:10s} {m.sum():7d} px  median {np.median(p.image[m]):7.3f} 1/cm  "
              f"std {p.image[m].std():.3f}")
