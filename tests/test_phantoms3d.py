"""The true 3D phantom: shapes and dtypes, its truth against the analytic shapes, the same
part for the same seed and a new tilt for a new one, and the interface distance against an
analytic sphere."""
import numpy as np
import pytest

from ctseg.errors import ParameterError
from ctseg.phantoms3d import (GRAY, MATERIALS, POLYMER_SD, _sdf, interface_distance,
                              interface_points, make_part_3d, make_sphere_3d)

SIZE = 40


@pytest.fixture(scope="module")
def parts():
    return {seed: make_part_3d(SIZE, seed=seed) for seed in (0, 1)}


def test_shapes_dtypes_and_fractions(parts):
    for ph in parts.values():
        assert ph.image.shape == ph.truth.shape == (SIZE,) * 3
        assert ph.image.dtype == np.float32 and ph.truth.dtype == np.uint8
        assert ph.labels_hr.shape == (SIZE * 2,) * 3
        assert ph.fractions.shape == (4, SIZE, SIZE, SIZE)
        assert np.allclose(ph.fractions.sum(axis=0), 1.0, atol=1e-6)
        assert np.array_equal(ph.truth, np.argmax(ph.fractions, axis=0))
        assert ph.names == MATERIALS and np.allclose(ph.gray, [GRAY[m] for m in MATERIALS])
        # the polymer is only POLYMER_SD noise sd above air; steel 10x the polymer's contrast
        assert ph.noise_sd == pytest.approx(GRAY["polymer"] / POLYMER_SD)
        assert GRAY["steel"] / GRAY["polymer"] == pytest.approx(10.0)
    assert {parts[0].features["housing"], parts[1].features["housing"]} == {"box", "cylinder"}


def test_every_material_present(parts):
    for ph in parts.values():
        assert np.array_equal(np.unique(ph.truth), np.arange(4))
        assert (ph.truth[[0, -1]] == 0).all() and (ph.truth[:, [0, -1]] == 0).all()  # air around
    big = make_part_3d(64, seed=0, keep_fractions=False)
    assert big.fractions is None and len(big.features["pores"]) >= 3
    assert all(2.0 <= r <= 4.0 for _, r in big.features["pores"])


def test_sdf_primitives():
    p = np.array([[3.0, 0, 0], [0, 0, 0], [2.0, 2.0, 0]])
    assert np.allclose(_sdf("sphere", ((0, 0, 0), 2.0), p), [1.0, -2.0, np.sqrt(8) - 2])
    assert np.allclose(_sdf("box", ((0, 0, 0), (1, 1, 1), 0.0), p), [2.0, -1.0, np.sqrt(2)])
    assert np.allclose(_sdf("cylinder", ((0, 0, 0), 1.0, 1.0, 0.0), p), [2.0, -1.0, np.sqrt(8) - 1])
    assert np.allclose(_sdf("tube", ((0, 0, 0), 2.0, 1.0, 0.0, 1.0), p), [1.0, 1.0, np.sqrt(8) - 2])


def test_truth_agrees_with_the_analytic_shapes(parts):
    for ph in parts.values():
        sc = ph.scene
        k, j, i = np.indices(ph.truth.shape).reshape(3, -1)
        local = (np.column_stack([i, j, k]) * ph.spacing - sc.centre) @ sc.rotation
        painted = np.full(len(local), sc.background)
        margin = np.full(len(local), np.inf)
        for label, kind, prm in sc.shapes:
            d = _sdf(kind, prm, local)
            painted[d < 0] = label
            margin = np.minimum(margin, np.abs(d))
        clear = margin > np.sqrt(3) / 2  # the whole voxel on one side of every shape
        assert clear.mean() > 0.8
        assert np.array_equal(ph.truth.ravel()[clear], painted[clear])
        assert np.all(ph.fractions.reshape(4, -1)[painted[clear], np.flatnonzero(clear)] == 1.0)
        # steel = the shaft (a cylinder) and the ball, painted last but for the pores in Al
        steel = [(kind, prm) for label, kind, prm in sc.shapes if label == 3]
        exact = sum(np.pi * prm[1] ** 2 * 2 * prm[2] if kind == "cylinder"
                    else 4 / 3 * np.pi * prm[1] ** 3 for kind, prm in steel)
        assert ph.fractions[3].sum() == pytest.approx(exact, rel=0.02)


def test_same_seed_same_part_new_seed_new_tilt(parts):
    again = make_part_3d(SIZE, seed=0)
    assert np.array_equal(again.image, parts[0].image)
    assert np.array_equal(again.labels_hr, parts[0].labels_hr)
    rots = [np.array(ph.features["rotation"])
            for ph in (parts[0], parts[1], make_part_3d(24, seed=2, porosity=False))]
    for r in rots:
        assert np.allclose(r @ r.T, np.eye(3)) and np.linalg.det(r) == pytest.approx(1.0)
        assert np.abs(r).max() < 0.99  # tilted: no axis of the part along a grid axis
    for a in range(3):
        for b in range(a):
            angle = np.degrees(np.arccos(np.clip((np.trace(rots[a].T @ rots[b]) - 1) / 2, -1, 1)))
            assert angle > 10
    assert not np.array_equal(parts[0].image, parts[1].image)


def test_variants():
    ph = make_part_3d(32, seed=3, materials=("air", "aluminium"), housing="box", porosity=False)
    assert ph.names == ("air", "aluminium") and set(np.unique(ph.truth)) == {0, 1}
    assert ph.features["housing"] == "box"
    aniso = make_part_3d(32, seed=3, spacing=(1.0, 1.0, 2.0), porosity=False)
    assert aniso.image.shape == (16, 32, 32)
    with pytest.raises(ParameterError):
        make_part_3d(16, materials=("steel", "air"))
    with pytest.raises(ParameterError):
        make_part_3d(16, housing="sphere")


@pytest.mark.parametrize("radius, supersample", [(9.3, 2), (2.6, 2), (6.1, 3), (9.3, 1)])
def test_interface_distance_to_an_analytic_sphere(radius, supersample):
    ph = make_sphere_3d(2 * int(radius) + 10, radius=radius, supersample=supersample)
    c = np.array(ph.features["centre"])
    rng = np.random.default_rng(1)
    u = rng.standard_normal((3000, 3))
    u /= np.linalg.norm(u, axis=1)[:, None]
    t = rng.uniform(-min(2.0, radius - 0.5), 3.0, len(u))
    err = interface_distance(ph, c + u * (radius + t)[:, None], 0, 1) - np.abs(t)
    near = np.abs(t) < 0.5
    assert np.abs(err).mean() < 0.015 and np.abs(err[near]).max() < 0.06
    assert np.abs(err).max() < 0.14 / supersample
    # the samples lie on the sphere
    P = interface_points(ph, 1, 0)
    assert np.abs(np.linalg.norm(P - c, axis=1) - radius).max() < 1e-3
    assert np.isinf(interface_distance(ph, c[None], 0, 2)).all()
