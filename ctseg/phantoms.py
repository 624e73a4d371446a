"""Simulated industrial CT slices with known truth (tests, benchmarks and the sample data).

A phantom is a label map painted from analytic shapes at ``supersample`` times the pixel
resolution; the CT simulation forward-projects each material's area fraction in parallel
beam, attenuates a polychromatic spectrum (beam hardening, photon starvation behind steel),
draws Poisson noise, and reconstructs by filtered back-projection (ramp filter, Shepp-Logan window).
"""
from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from .projection import filtered_backprojection

# Linear attenuation (1/cm) at the spectrum's energy bins, from NIST XCOM mass attenuation
# coefficients times density (steel 7.87, aluminium 2.70, POM polymer 1.41 g/cm^3).
ENERGIES_KEV = np.array([40.0, 60.0, 80.0, 100.0, 150.0])
SPECTRUM = np.array([0.02, 0.15, 0.30, 0.30, 0.23])  # 160 kV tungsten, 2 mm Cu filtered
MU = {
    "air": np.zeros(5),
    "polymer": 1.41 * np.array([0.263, 0.199, 0.178, 0.165, 0.144]),
    "aluminium": 2.70 * np.array([0.568, 0.278, 0.202, 0.170, 0.138]),
    "steel": 7.87 * np.array([3.63, 1.21, 0.596, 0.372, 0.196]),
}
MATERIALS = ("air", "polymer", "aluminium", "steel")


@dataclass
class Phantom:
    """A simulated slice: ``image`` (float32, 1/cm), ``truth`` (uint8 labels per pixel, by
    majority of the supersampled map), ``truth_hr`` (the supersampled labels), materials
    named in ``names`` (label k = names[k], ascending attenuation)."""

    image: np.ndarray
    truth: np.ndarray
    truth_hr: np.ndarray
    supersample: int
    names: tuple
    pixel_mm: float


def _label_of(name, materials):
    """Label of material ``name`` among ``materials``, or of the closest present one in
    attenuation order (the denser one first) when it is absent."""
    order = list(MATERIALS)
    i = order.index(name)
    for d in range(len(order)):
        for j in (i + d, i - d):
            if 0 <= j < len(order) and order[j] in materials:
                return list(materials).index(order[j])
    return 0


def _disc(x, y, cx, cy, r):
    return (x - cx) ** 2 + (y - cy) ** 2 <= r * r


def _box(x, y, cx, cy, hw, hh, angle=0.0):
    c, s = np.cos(angle), np.sin(angle)
    u = (x - cx) * c + (y - cy) * s
    v = -(x - cx) * s + (y - cy) * c
    return (np.abs(u) <= hw) & (np.abs(v) <= hh)


def part_labels(size, seed=0, supersample=4, materials=MATERIALS, porosity=True):
    """Paint a multi-material part: housing with bore, bushing, shaft, bolt holes, fins, pores.

    Coordinates are in pixels of the final image (centre of pixel (r, c) at x=c, y=r).
    ``materials`` picks which of air/polymer/aluminium/steel appear; the shapes of a missing
    material take the nearest present one in the list order. Returns uint8 labels at
    ``supersample`` resolution, 0..len(materials)-1 in the given order.
    """
    rng = np.random.default_rng(seed)
    n = size * supersample
    coords = (np.arange(n) + 0.5) / supersample - 0.5
    x, y = np.meshgrid(coords, coords)
    lab = np.zeros((n, n), np.uint8)

    def code(name):
        return _label_of(name, materials)

    S = float(size)
    cx, cy = S / 2 + rng.uniform(-0.03, 0.03) * S, S / 2 + rng.uniform(-0.03, 0.03) * S
    r_house = rng.uniform(0.36, 0.40) * S
    r_bore = rng.uniform(0.16, 0.19) * S
    r_bush = r_bore - rng.uniform(0.035, 0.05) * S
    r_shaft = r_bush - rng.uniform(0.02, 0.03) * S
    al, st, po = code("aluminium"), code("steel"), code("polymer")
    lab[_disc(x, y, cx, cy, r_house)] = al
    # fins: thin aluminium walls, 4-6 px thick at 512 px (0.3-0.5 mm)
    for k in range(rng.integers(3, 6)):
        ang = rng.uniform(0, 2 * np.pi)
        t = rng.uniform(2.0, 3.0) * S / 512
        L = rng.uniform(0.05, 0.08) * S
        fx, fy = cx + (r_house + L / 2 - 2) * np.cos(ang), cy + (r_house + L / 2 - 2) * np.sin(ang)
        lab[_box(x, y, fx, fy, L / 2, t, ang)] = al
    lab[_disc(x, y, cx, cy, r_bore)] = code("air")
    lab[_disc(x, y, cx, cy, r_bush)] = po
    lab[_disc(x, y, cx, cy, r_shaft)] = st
    # bolt holes, some with steel bolts, some empty
    nb = int(rng.integers(4, 7))
    r_ring = 0.5 * (r_bore + r_house)
    for k in range(nb):
        ang = 2 * np.pi * k / nb + rng.uniform(-0.1, 0.1)
        bx, by = cx + r_ring * np.cos(ang), cy + r_ring * np.sin(ang)
        rh = rng.uniform(0.025, 0.035) * S
        lab[_disc(x, y, bx, by, rh)] = code("air")
        if k == 0:  # one steel bolt in an air gap of 3-5 px
            lab[_disc(x, y, bx, by, rh - rng.uniform(3.0, 5.0) * S / 512)] = st
    # a polymer cover plate outside the housing, with a thin polymer lip
    px_, py_ = cx + rng.uniform(-0.05, 0.05) * S, cy - r_house - 0.06 * S
    lab[_box(x, y, px_, py_, 0.16 * S, 0.025 * S)] = po
    lab[_box(x, y, px_ + 0.18 * S, py_ + 0.02 * S, 0.04 * S, 3.0 * S / 512)] = po
    if porosity:
        # gas pores in the aluminium: radius 1.5-4 px
        for _ in range(int(rng.integers(6, 12))):
            for _try in range(20):
                a = rng.uniform(0, 2 * np.pi)
                rr = rng.uniform(r_bore + 0.03 * S, r_house - 0.03 * S)
                qx, qy = cx + rr * np.cos(a), cy + rr * np.sin(a)
                i = int(round((qy + 0.5) * supersample - 0.5))
                j = int(round((qx + 0.5) * supersample - 0.5))
                if lab[np.clip(i, 0, n - 1), np.clip(j, 0, n - 1)] == al:
                    lab[_disc(x, y, qx, qy, rng.uniform(2.0, 5.0) * S / 512)] = code("air")
                    break
    return lab


def _downsample_fractions(lab_hr, s, n_labels):
    n = lab_hr.shape[0] // s
    frac = np.zeros((n_labels, n, n))
    for k in range(n_labels):
        frac[k] = (lab_hr == k).reshape(n, s, n, s).mean(axis=(1, 3))
    return frac


def _radon(maps, angles):
    """Parallel-beam line integrals (pixel units) of each map: (k, n_angles, n_det).

    The detector spans the image diagonal so that the whole square is reconstructed.
    Ray-driven (bilinear samples along each ray), deliberately not the pixel-driven
    :func:`ctseg.projection.forward_project` that the streak correction uses: data made
    with the corrector's own projector would flatter it.
    """
    k, n, _ = maps.shape
    c = (n - 1) / 2.0
    n_det = int(np.ceil(n * np.sqrt(2.0))) | 1
    t = np.arange(n_det) - (n_det - 1) / 2.0
    out = np.empty((k, len(angles), n_det))
    ss, tt = np.meshgrid(t, t, indexing="ij")  # ss: along the ray, tt: detector
    for a, th in enumerate(angles):
        ct, st = np.cos(th), np.sin(th)
        xs = c + tt * ct - ss * st
        ys = c + tt * st + ss * ct
        for m in range(k):
            out[m, a] = ndimage.map_coordinates(maps[m], [ys, xs], order=1, mode="constant").sum(axis=0)
    return out


def simulate_ct(labels_hr, supersample, materials=MATERIALS, pixel_mm=0.08, photons=1e6,
                n_angles=None, seed=0):
    """Simulate a polychromatic parallel-beam CT scan and its FBP reconstruction.

    Parameters
    ----------
    labels_hr : (n*s, n*s) uint8 ndarray
        Material labels at ``supersample`` times the image resolution.
    supersample : int
    materials : tuple of str
        Name of each label, keys of :data:`MU`.
    pixel_mm : float
        Pixel size; sets the path lengths and so the beam hardening.
    photons : float
        Unattenuated photon count per detector bin (sets the noise).
    n_angles : int, optional
        Projections over 180 degrees; default the image width.
    seed : int

    Returns
    -------
    image : (n, n) float32 ndarray
        Reconstructed linear attenuation in 1/cm.
    """
    rng = np.random.default_rng(seed)
    s = supersample
    n = labels_hr.shape[0] // s
    frac = _downsample_fractions(labels_hr, s, len(materials))
    angles = np.linspace(0, np.pi, n_angles or n, endpoint=False)
    dense = [k for k, m in enumerate(materials) if m != "air"]
    L_cm = _radon(frac[dense], angles) * pixel_mm / 10.0  # path length per material, cm
    mu = np.array([MU[materials[k]] for k in dense])  # (k, E)
    att = np.einsum("kad,ke->ade", L_cm, mu)
    expected = photons * np.einsum("ade,e->ad", np.exp(-att), SPECTRUM / SPECTRUM.sum())
    counts = np.maximum(rng.poisson(expected), 1)
    sino = -np.log(counts / photons)
    sino = ndimage.gaussian_filter1d(sino, 0.6, axis=1)  # detector blur
    rec = filtered_backprojection(sino, angles, (n, n)) / (pixel_mm / 10.0)
    return rec.astype(np.float32)


def make_phantom(size=256, seed=0, materials=MATERIALS, supersample=4, photons=1e6,
                 pixel_mm=None, porosity=True):
    """A simulated slice of a multi-material part with its truth (see :func:`part_labels`).

    The default pixel size scales with the image so the part is about 40 mm across.
    """
    if pixel_mm is None:
        pixel_mm = 40.0 / size
    hr = part_labels(size, seed=seed, supersample=supersample, materials=materials,
                     porosity=porosity)
    img = simulate_ct(hr, supersample, materials=materials, pixel_mm=pixel_mm,
                      photons=photons, seed=seed + 1)
    frac = _downsample_fractions(hr, supersample, len(materials))
    truth = np.argmax(frac, axis=0).astype(np.uint8)
    return Phantom(image=img, truth=truth, truth_hr=hr, supersample=supersample,
                   names=tuple(materials), pixel_mm=pixel_mm)


@dataclass
class VolumePhantom:
    """A simulated volume: ``image`` (nz, ny, nx) float32, ``truth`` (nz, ny, nx) uint8
    labels by majority of each voxel's in-plane supersampled area, ``names`` per label."""

    image: np.ndarray
    truth: np.ndarray
    names: tuple


def volume_labels_hr(n_slices, size, seed=0, supersample=2, materials=MATERIALS):
    """Label a 3D part slice by slice, at ``supersample`` times the in-plane resolution.

    An aluminium housing (absent from the first and last tenth of the slices, which are
    air only), a bore lined with a polymer bushing in the middle slices, a steel shaft
    through the upper part, a steel ball and spherical gas pores of 2-4 px radius. Shapes
    of materials not in ``materials`` take the closest present one (see :func:`part_labels`).

    Returns
    -------
    labels : (n_slices, size * s, size * s) uint8 ndarray
    """
    rng = np.random.default_rng(seed)
    n = size * supersample
    coords = (np.arange(n) + 0.5) / supersample - 0.5
    x, y = np.meshgrid(coords, coords)

    def code(name):
        return _label_of(name, materials)

    S, nz = float(size), n_slices
    cx, cy = S / 2 + rng.uniform(-0.03, 0.03) * S, S / 2 + rng.uniform(-0.03, 0.03) * S
    r_house, r_bore = rng.uniform(0.36, 0.40) * S, rng.uniform(0.17, 0.19) * S
    r_bush, r_shaft = r_bore - 0.06 * S, r_bore - 0.11 * S
    ball = (cx + 0.27 * S, cy, 0.5 * nz, 0.06 * S)
    pores = []
    while len(pores) < 10:
        a, rr = rng.uniform(0, 2 * np.pi), rng.uniform(r_bore + 0.04 * S, r_house - 0.04 * S)
        qx, qy = cx + rr * np.cos(a), cy + rr * np.sin(a)
        if np.hypot(qx - ball[0], qy - ball[1]) > ball[3] + 6:
            pores.append((qx, qy, rng.uniform(0.1, 0.9) * nz, rng.uniform(2.0, 4.0) * S / 256))
    lab = np.zeros((nz, n, n), np.uint8)
    for k in range(nz):
        z = k + 0.0
        if not (0.1 * nz <= z < 0.9 * nz):
            continue
        sl = lab[k]
        sl[_disc(x, y, cx, cy, r_house)] = code("aluminium")
        sl[_disc(x, y, cx, cy, r_bore)] = code("air")
        if 0.2 * nz <= z < 0.8 * nz:
            sl[_disc(x, y, cx, cy, r_bore)] = code("polymer")
            sl[_disc(x, y, cx, cy, r_bush)] = code("air")
        if z >= 0.3 * nz:
            sl[_disc(x, y, cx, cy, r_shaft)] = code("steel")
        for qx, qy, qz, qr in pores + [ball]:
            dz = z - qz
            if abs(dz) < qr:
                fill = code("steel") if (qx, qy, qz, qr) == ball else code("air")
                sl[_disc(x, y, qx, qy, np.sqrt(qr * qr - dz * dz))] = fill
    return lab


def make_volume(n_slices=16, size=96, seed=0, materials=MATERIALS, supersample=2,
                noise=0.04, simulate=False, photons=1e6):
    """A simulated CT volume of a multi-material part with its voxel truth.

    With ``simulate=True`` every slice is a polychromatic CT simulation
    (:func:`simulate_ct`: beam hardening, streaks, Poisson noise, FBP); otherwise (fast,
    for tests) each slice is the materials' mean attenuation mixed by area fraction
    (partial volume), blurred by a 0.7 px Gaussian, plus Gaussian noise of ``noise``
    times the aluminium attenuation.

    Returns
    -------
    VolumePhantom
    """
    hr = volume_labels_hr(n_slices, size, seed=seed, supersample=supersample,
                          materials=materials)
    pixel_mm = 40.0 / size
    mean_mu = np.array([float(MU[m] @ SPECTRUM) / SPECTRUM.sum() for m in materials])
    rng = np.random.default_rng(seed + 1)
    image = np.empty((n_slices, size, size), np.float32)
    truth = np.empty((n_slices, size, size), np.uint8)
    for k in range(n_slices):
        frac = _downsample_fractions(hr[k], supersample, len(materials))
        truth[k] = np.argmax(frac, axis=0)
        if simulate:
            image[k] = simulate_ct(hr[k], supersample, materials=materials, pixel_mm=pixel_mm,
                                   photons=photons, seed=seed + 1 + k)
        else:
            clean = ndimage.gaussian_filter(np.tensordot(mean_mu, frac, axes=1), 0.7)
            scale = float(MU["aluminium"] @ SPECTRUM) / SPECTRUM.sum()
            image[k] = clean + noise * scale * rng.standard_normal((size, size))
    return VolumePhantom(image=image, truth=truth, names=tuple(materials))
