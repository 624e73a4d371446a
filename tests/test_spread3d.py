"""benchmarks/spread3d.py: its unperturbed run is the default run, and it leaves the
pipeline as it found it."""
import os
import sys

import numpy as np

import ctseg
import ctseg.pipeline3d as pipeline3d
from ctseg.phantoms3d import make_part_3d

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "benchmarks"))
import spread3d  # noqa: E402
import volume3d  # noqa: E402


def test_unperturbed_run_is_the_default_and_the_pipeline_is_restored():
    before = pipeline3d.density_3d
    rows, names = spread3d.run(40, 0, 2)
    assert pipeline3d.density_3d is before
    assert [(r["capped"], r["k"]) for r in rows] == [(False, 0), (False, 1), (True, 0), (True, 1)]
    ph = make_part_3d(40, seed=0)
    seg = ctseg.segment_volume(ph.image, mode="3d", spacing=ph.spacing)
    labels, gray, extra, arrays = volume3d.post("ctseg_3d", seg, ph.image, ph.spacing)
    arrays["labels"] = labels
    ev = volume3d.evaluate(ph, dict(class_gray=gray, **extra), arrays, volume3d.aux_maps(ph))
    default = rows[2]  # the raise in use, no perturbation: what segment_volume does
    assert default["dice"] == ev["dice"] and names == list(ph.names)
    assert default["voxels_wrong"] == ph.truth.size - np.trace(np.asarray(ev["confusion"]))
    assert "| 40^3 seed 0 | yes | 2 |" in spread3d.summary(rows, names)


def test_overrides_are_parsed_by_the_parameter_spec():
    assert spread3d.parse_overrides(["fine_iter_3d=10", "density_saturation=auto"]) == {
        "fine_iter_3d": 10, "density_saturation": "auto"}
