"""Phase fractions of real snow and concrete slices against the hand reference of
benchmarks/realdata_fractions.py (levels read off rectangles drawn by eye, ISO-50 between
them): the defaults must find both phases and stay within 3 points. Skipped without
../shared/realdata (a user's checkout)."""
import os
import sys

import numpy as np
import pytest

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "benchmarks"))
from realdata_fractions import HAND, REALDATA, run_scan  # noqa: E402

pytestmark = pytest.mark.skipif(not os.path.isdir(REALDATA), reason="../shared/realdata is absent")


@pytest.mark.parametrize("name", sorted(HAND))
def test_slices_within_three_points_of_the_hand_reference(name):
    levels, rows = run_scan(name, with_3d=False)
    assert len(rows) == len(HAND[name]["slices"])
    for r in rows:
        assert r["n_materials"] >= 2, r
        assert abs(r["ctseg"] - r["reference"]) <= 0.03, r
    if name == "snow":  # ice and air both large: the masks must agree pixel by pixel too
        assert min(r["dice"] for r in rows) >= 0.93
    else:  # the pores are small: at least the large ones found
        assert max(r["dice"] for r in rows) >= 0.5


def test_hand_rectangles_are_single_phases():
    """Each rectangle drawn by eye lies inside one phase: its spread is small against the
    phases' separation."""
    for spec in HAND.values():
        vol = np.load(os.path.join(REALDATA, spec["file"]))
        from realdata_fractions import hand_levels

        lv = hand_levels(vol.astype(float), spec["rects"])
        (lo, s_lo), (hi, s_hi) = sorted(lv.values())
        assert hi - lo > 10 * max(s_lo, s_hi)
