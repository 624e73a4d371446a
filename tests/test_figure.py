"""The paper's Fig. 5, rendered with VTK offscreen: what the panels show, checked on pixels."""
import numpy as np
import pytest

import ctseg
from ctseg.errors import InputError
from ctseg.filters.figure import PANEL_PX, TITLE_PX, render_figure
from ctseg.filters.writers import PALETTE

from conftest import disc_image, requires_rendering


@requires_rendering
def test_six_panels_show_the_image_and_the_materials(tmp_path):
    img, truth = disc_image(64, noise=3.0)
    seg = ctseg.segment_image(img, n_sites=150)
    rgb = render_figure(tmp_path / "f.png", img, seg, title="disc")
    scale = PANEL_PX / 64
    pw = ph = int(round(64 * scale))
    assert rgb.shape == (2 * (ph + TITLE_PX), 3 * pw, 3)
    assert (tmp_path / "f.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"

    def panel(k):
        r0 = (k // 3) * (ph + TITLE_PX) + TITLE_PX
        return rgb[r0:r0 + ph, (k % 3) * pw:(k % 3 + 1) * pw].astype(int)

    # the truth at panel resolution (rows flipped: the picture has y up)
    idx = (np.arange(pw) / scale).astype(int)
    disc = truth[::-1][idx][:, idx].astype(bool)
    inp = panel(0)[..., 0]
    assert inp[disc].mean() > 150 > 60 > inp[~disc].mean()
    # materials: the disc's share of the panel in material 1's colour, air in material 0's
    mats = panel(4)
    share1 = np.all(mats == PALETTE[1], axis=2).mean()
    share0 = np.all(mats == PALETTE[0], axis=2).mean()
    assert 0.6 * truth.mean() < share1 < 1.05 * truth.mean()
    assert 0.6 * (1 - truth.mean()) < share0 < 1.05 * (1 - truth.mean())
    # boundaries: red pixels all round the disc, and only near its true edge
    from scipy.ndimage import distance_transform_edt

    red = (panel(5)[..., 0] > 200) & (panel(5)[..., 1] < 90)
    to_edge = np.maximum(distance_transform_edt(disc), distance_transform_edt(~disc))
    assert red.sum() > 2 * np.pi * 0.3 * 64 * scale  # at least the circumference, 1 px wide
    assert np.mean(to_edge[red] <= 2 * scale) > 0.98


def test_figure_needs_the_maps_and_a_png_name(tmp_path):
    img, _ = disc_image(32)
    seg = ctseg.segment_image(img, n_sites=40)
    with pytest.raises(InputError, match="unknown output format"):
        render_figure(tmp_path / "f.jpg", img, seg)
    seg.density = None
    with pytest.raises(InputError, match="no density"):
        render_figure(tmp_path / "f.png", img, seg)
