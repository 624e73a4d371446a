"""Parallel-beam projection and FBP (ctseg.projection) against analytic values and a slow reference."""
import numpy as np
import pytest

from ctseg.projection import detector_bins, filtered_backprojection, forward_project


def disc(shape, cy, cx, r):
    yy, xx = np.mgrid[0:shape[0], 0:shape[1]]
    return ((yy - cy) ** 2 + (xx - cx) ** 2 <= r * r).astype(float)


def reference_fbp(sino, angles, shape):
    """Slow and obvious: ramp x sinc filter by FFT, then np.interp per angle and pixel."""
    n_det = sino.shape[1]
    pad = int(2 ** np.ceil(np.log2(2 * n_det)))
    freq = np.fft.fftfreq(pad)
    proj = np.fft.ifft(np.fft.fft(sino, pad, axis=1) * 2 * np.abs(freq) * np.sinc(freq),
                       axis=1).real[:, :n_det]
    t_axis = np.arange(n_det) - (n_det - 1) / 2.0
    rec = np.zeros(shape)
    for r in range(shape[0]):
        for c in range(shape[1]):
            x, y = c - (shape[1] - 1) / 2.0, r - (shape[0] - 1) / 2.0
            for a, th in enumerate(angles):
                rec[r, c] += np.interp(x * np.cos(th) + y * np.sin(th), t_axis, proj[a],
                                       left=0, right=0)
    return rec * np.pi / (2 * len(angles))


def test_projection_keeps_mass_and_centre_at_every_angle():
    # linear sharing between two bins keeps each point's weight and mean position exactly
    rng = np.random.default_rng(0)
    img = rng.random((23, 31)) * (rng.random((23, 31)) < 0.3)
    angles = np.linspace(0, np.pi, 17, endpoint=False)
    sino = forward_project(img, angles)
    n_det = detector_bins(img.shape)
    assert sino.shape == (17, n_det)
    t = np.arange(n_det) - (n_det - 1) / 2.0
    yy, xx = np.mgrid[0:23, 0:31]
    x, y = xx - 15.0, yy - 11.0
    for a, th in enumerate(angles):
        assert sino[a].sum() == pytest.approx(img.sum(), rel=1e-12)
        expected = (img * (x * np.cos(th) + y * np.sin(th))).sum()
        assert (sino[a] * t).sum() == pytest.approx(expected, rel=1e-9, abs=1e-9)


def test_projection_of_a_disc_matches_its_chord_lengths():
    shape, r = (101, 101), 30.0
    angles = np.linspace(0, np.pi, 12, endpoint=False)
    sino = forward_project(disc(shape, 50, 50, r), angles)
    t = np.arange(sino.shape[1]) - (sino.shape[1] - 1) / 2.0
    chord = 2 * np.sqrt(np.clip(r * r - t * t, 0, None))
    inside = np.abs(t) < r - 2
    # a disc of whole pixels is not a true disc: up to a pixel at each end of a chord
    err = np.abs(sino[:, inside] - chord[inside])
    assert err.max() < 2.0 and err.mean() < 0.4
    assert np.abs(sino[:, np.abs(t) > r + 2]).max() == 0.0


@pytest.mark.parametrize("shape", [(12, 12), (9, 14)])
def test_fbp_equals_slow_reference(shape):
    rng = np.random.default_rng(1)
    angles = np.linspace(0, np.pi, 7, endpoint=False)
    sino = rng.normal(size=(7, detector_bins(shape)))
    np.testing.assert_allclose(filtered_backprojection(sino, angles, shape),
                               reference_fbp(sino, angles, shape), rtol=1e-10, atol=1e-12)


def test_fbp_of_projections_reconstructs_the_image():
    shape = (64, 80)  # not square: the centre and the detector must follow both sides
    img = disc(shape, 30, 45, 12) + 0.5 * disc(shape, 40, 20, 6)
    angles = np.linspace(0, np.pi, 120, endpoint=False)
    rec = filtered_backprojection(forward_project(img, angles), angles, shape)
    core_big = disc(shape, 30, 45, 9).astype(bool)
    core_small = disc(shape, 40, 20, 3).astype(bool)
    far = (disc(shape, 30, 45, 16) + disc(shape, 40, 20, 10)) == 0
    assert rec[core_big].mean() == pytest.approx(1.0, abs=0.03)
    assert rec[core_small].mean() == pytest.approx(0.5, abs=0.03)
    assert np.abs(rec[far]).mean() < 0.01


def test_threaded_and_serial_fbp_give_the_same_bits(monkeypatch):
    """One process back-projects bands of rows in threads, slice workers serially: each
    pixel adds the angles in the same order, so the same bits (rows not a multiple of the
    band)."""
    from ctseg import _threads

    shape = (37, 29)
    rng = np.random.default_rng(4)
    angles = np.linspace(0, np.pi, 23, endpoint=False)
    sino = rng.normal(size=(23, detector_bins(shape)))
    runs = []
    for threaded in (True, False):
        monkeypatch.setattr(_threads, "enabled", threaded)
        runs.append(filtered_backprojection(sino, angles, shape))
    assert np.array_equal(runs[0], runs[1])
    np.testing.assert_allclose(runs[0], reference_fbp(sino, angles, shape), rtol=1e-10, atol=1e-12)
