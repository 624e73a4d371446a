"""A second CT simulator, independent of :mod:`ctseg.phantoms`: fan beam, exact line
integrals, other materials and spectra, detector effects and 8-bit export.

ctseg's defaults were tuned on :func:`ctseg.phantoms.make_phantom` (parallel beam,
ray-driven projection of a fraction map, four materials, five energy bins). This module
measures them on data made another way:

* geometry and projector: a flat-detector fan beam over 360 degrees; each channel averages
  the intensities of three exact rays across its width, the path lengths through analytic
  shapes solved in closed form (:mod:`ctseg.fan_beam`); weighted fan-beam FBP with a
  Hann-windowed ramp;
* physics: a tungsten-anode spectrum (Kramers' law plus K lines, 120-160 kV, filtered) on
  energy bins of 5 keV and attenuation from the NIST mass attenuation tables
  (:mod:`ctseg.xray_spectra`), so beam hardening, cupping and the streaks between metal
  parts arise from the transmission itself; an energy-integrating detector;
* detector and scanner: scatter (a smooth additive term on the intensities, widely blurred
  interactions of the primary beam), Poisson noise, crosstalk between neighbouring channels
  (detector blur), per-channel gain errors not flat-fielded away (ring artefacts), and
  optionally an 8-bit export whose window saturates the densest material;
* parts (:data:`PARTS`): metal inserts in a plate, a PEEK body with an alumina ceramic ring
  and balls, a carbon-fibre lap joint with a titanium fastener.

The truth follows :func:`ctseg.phantoms.make_phantom`'s conventions: labels ascending in
the attenuation the scan shows, ``truth`` the per-pixel majority of the supersampled
``truth_hr``, so ``ctseg.metrics.evaluate(seg, p.truth, p.truth_hr, p.supersample)`` works.
"""
from dataclasses import dataclass, field

import numpy as np
from scipy import ndimage

from .fan_beam import Scene, fan_fbp, fan_geometry, path_lengths
from .phantoms import Phantom
from .xray_spectra import effective_attenuation, linear_attenuation, tungsten_spectrum

PARTS = ("inserts", "ceramic", "composite")
"""The part layouts :func:`make_fan_phantom` draws."""


@dataclass
class FanPhantom(Phantom):
    """A simulated fan-beam slice: :class:`ctseg.phantoms.Phantom`'s fields (``image``
    float32 in 1/cm, or uint8 when clipped to 8 bits), plus the 8-bit ``window`` (1/cm, or
    None) and the simulation's settings."""

    window: tuple = None
    settings: dict = field(default_factory=dict)


def _inserts(sc, S, rng, plate="aluminium", metals=("steel", "copper", "titanium")):
    """Metal discs in a plate, several on one line so rays pass through two or three."""
    cx, cy = S / 2 + rng.uniform(-0.02, 0.02) * S, S / 2 + rng.uniform(-0.02, 0.02) * S
    ang = rng.uniform(-0.35, 0.35)
    hw, hh = rng.uniform(0.34, 0.38) * S, rng.uniform(0.18, 0.22) * S
    sc.box(cx, cy, hw, hh, ang, plate)
    c, s = np.cos(ang), np.sin(ang)
    n = int(rng.integers(3, 6))
    spacing = 1.4 * hw / (n - 1)
    xs = np.linspace(-0.70, 0.70, n) * hw + rng.uniform(-0.01, 0.01, n) * S
    ys = rng.choice([-0.3, 0.0, 0.3], n, p=[0.2, 0.6, 0.2]) * hh
    for k in range(n):
        px, py = cx + xs[k] * c - ys[k] * s, cy + xs[k] * s + ys[k] * c
        r = rng.uniform(0.03 * S, min(0.06 * S, 0.38 * spacing))
        metal = metals[k % len(metals)]
        if k == 1:  # a press-fit sleeve: air gap of 2-3 px, metal ring, plate material core
            sc.disc(px, py, r + rng.uniform(2.0, 3.0) * S / 512, "air")
            sc.disc(px, py, r, metal)
            sc.disc(px, py, 0.5 * r, plate)
        else:
            sc.disc(px, py, r, metal)
    for _ in range(2):  # drilled holes off the insert line
        u, v = rng.uniform(-0.8, 0.8) * hw, rng.choice([-1, 1]) * 0.8 * hh
        sc.disc(cx + u * c - v * s, cy + u * s + v * c, rng.uniform(0.015, 0.025) * S, "air")


def _ceramic(sc, S, rng, body="peek", ceramic="alumina"):
    """A PEEK bearing housing with an alumina ring, alumina balls and a keyway."""
    cx, cy = S / 2 + rng.uniform(-0.02, 0.02) * S, S / 2 + rng.uniform(-0.02, 0.02) * S
    r_body = rng.uniform(0.36, 0.40) * S
    sc.ellipse(cx, cy, r_body, r_body * rng.uniform(0.95, 1.0), rng.uniform(0, np.pi), body)
    r_ring = rng.uniform(0.13, 0.16) * S
    sc.disc(cx, cy, r_ring, ceramic)
    sc.disc(cx, cy, r_ring - rng.uniform(0.03, 0.045) * S, body)
    sc.disc(cx, cy, rng.uniform(0.05, 0.07) * S, "air")
    a0 = rng.uniform(0, 2 * np.pi)
    sc.box(cx + 0.065 * S * np.cos(a0), cy + 0.065 * S * np.sin(a0), 0.02 * S, 0.012 * S, a0, "air")
    nb = int(rng.integers(6, 10))
    r_pitch = 0.5 * (r_ring + r_body)
    rb = min(0.045 * S, 0.4 * (r_body - r_ring))
    for k in range(nb):
        a = a0 + 2 * np.pi * k / nb
        sc.disc(cx + r_pitch * np.cos(a), cy + r_pitch * np.sin(a), rb, ceramic)


def _composite(sc, S, rng, plate="cfrp", fastener="titanium", backing="aluminium"):
    """Two carbon-fibre plates in a lap joint, a metal fastener through both with its head
    and collar, an aluminium backing strip and a delamination."""
    cx, cy = S / 2 + rng.uniform(-0.02, 0.02) * S, S / 2 + rng.uniform(-0.02, 0.02) * S
    ang = rng.uniform(-0.25, 0.25)
    c, s = np.cos(ang), np.sin(ang)
    t = rng.uniform(0.055, 0.07) * S  # half thickness of one plate

    def at(u, v):
        return cx + u * c - v * s, cy + u * s + v * c

    sc.box(*at(-0.12 * S, -t), 0.30 * S, t, ang, plate)
    sc.box(*at(0.12 * S, t), 0.30 * S, t, ang, plate)
    sc.box(*at(-0.05 * S, 2 * t + 0.03 * S), 0.20 * S, 0.03 * S, ang, backing)
    sc.box(*at(-0.30 * S, -t + rng.uniform(-0.4, 0.4) * t), 0.07 * S, 1.0 * S / 512, ang, "air")
    shank = rng.uniform(0.03, 0.04) * S
    # clearance hole through both plates and the strip, then the shank in it
    sc.box(*at(0.0, 0.03 * S), shank + 2.0 * S / 512, 2 * t + 0.03 * S, ang, "air")
    sc.box(*at(0.0, 0.0), shank, 2 * t + 0.09 * S, ang, fastener)
    sc.box(*at(0.0, -2 * t - 0.035 * S), 1.9 * shank, 0.035 * S, ang, fastener)  # head
    # collar on the far side, beyond the backing strip
    sc.box(*at(0.0, 2 * t + 0.075 * S), 1.6 * shank, 0.015 * S, ang, fastener)


_LAYOUTS = {"inserts": _inserts, "ceramic": _ceramic, "composite": _composite}


def part_scene(part, size, seed=None, **layout):
    """The shapes of a part and the names of its materials in painting terms.

    Parameters
    ----------
    part : str
        One of :data:`PARTS`.
    size : int
        Image side (px); the shapes scale with it.
    seed : int, optional
        Draws the layout (None: 0).
    **layout
        Material choices of the layout: ``plate``, ``metals`` (inserts); ``body``,
        ``ceramic``; ``plate``, ``fastener``, ``backing`` (composite).

    Returns
    -------
    scene : ctseg.fan_beam.Scene
        Shapes labelled by material name (strings), see :func:`make_fan_phantom`.

    Example
    -------
    >>> sorted(set(part_scene("ceramic", 64).label))
    ['air', 'alumina', 'peek']
    """
    rng = np.random.default_rng(0 if seed is None else seed)
    sc = _NamedScene()
    _LAYOUTS[part](sc, float(size), rng, **layout)
    return sc


class _NamedScene(Scene):
    """A Scene whose labels are material names until :meth:`numbered`."""

    def ellipse(self, cx, cy, a, b, angle, label):
        super().ellipse(cx, cy, a, b, angle, 0)
        self.label[-1] = label

    def polygon(self, vertices, label):
        super().polygon(vertices, 0)
        self.label[-1] = label

    def numbered(self, names):
        sc = Scene()
        for attr in ("kind", "ellipse_par", "sides", "bound"):
            setattr(sc, attr, list(getattr(self, attr)))
        sc.label = [names.index(m) for m in self.label]
        return sc


def simulate_fan_ct(scene, n_labels, mu, size, pixel_mm, photons=2e5, scatter=0.01, ring=0.003,
                    crosstalk=0.25, n_views=None, seed=None, chunk=64):
    """Scan a numbered scene in fan beam and reconstruct it (1/cm).

    Parameters
    ----------
    scene : ctseg.fan_beam.Scene
        Shapes labelled 0..n_labels-1.
    n_labels : int
    mu : tuple (weights, mu_e)
        ``weights`` (E,): each energy bin's share of the detector signal (sums to 1);
        ``mu_e`` (n_labels, E): linear attenuation (1/cm) of each label in each bin.
    size : int
    pixel_mm : float
    photons : float
        Unattenuated photons per channel and view; 0 for no noise.
    scatter : float
        Scatter amplitude: share of the primary's interactions that reach the detector.
    ring : float
        Relative standard deviation of the channel gains (not flat-fielded).
    crosstalk : float
        Share of a channel's signal that leaks to each neighbour (detector blur).
    n_views : int, optional
        Default twice the image side.
    seed : int, optional
        Noise and gains (None: 0).
    chunk : int
        Views projected at a time (bounds the memory).

    Returns
    -------
    image : (size, size) float32 ndarray

    Example
    -------
    >>> sc = Scene(); sc.disc(15.5, 15.5, 8.0, 1)
    >>> mono = (np.array([1.0]), np.array([[0.0], [1.0]]))
    >>> img = simulate_fan_ct(sc, 2, mono, 32, 1.0, photons=0, scatter=0, ring=0, crosstalk=0)
    >>> bool(abs(float(img[14:18, 14:18].mean()) - 1.0) < 0.05)
    True
    """
    weights, mu_e = (np.asarray(a, float) for a in mu)
    w32, mu32 = weights.astype(np.float32), mu_e.astype(np.float32)
    cm = pixel_mm / 10.0
    rng = np.random.default_rng(0 if seed is None else seed)
    geom = fan_geometry(size, n_views=n_views)
    primary = np.empty((geom.n_views, geom.n_det))
    for v0 in range(0, geom.n_views, chunk):
        views = slice(v0, min(v0 + chunk, geom.n_views))
        o, d = geom.rays(views)
        L = path_lengths(scene, o.reshape(-1, 2), d.reshape(-1, 2), n_labels) * cm
        # polychromatic transmission, each sub-ray separately: the channel averages
        # intensities, not line integrals (exponential edge-gradient effect)
        # (float32: 7 times faster, and exp keeps its relative precision down to 1e-30)
        trans = np.exp(-(L.astype(np.float32) @ mu32)) @ w32
        primary[views] = trans.reshape(o.shape[:-1]).mean(axis=-1)
    signal = primary.copy()
    if scatter:
        # interactions (1 - T), attenuated on the way out (sqrt T), spread over a wide
        # angle: a smooth additive term that dominates behind metal
        spread = ndimage.gaussian_filter1d((1 - primary) * np.sqrt(primary), geom.n_det / 8.0,
                                           axis=1, mode="nearest", truncate=3.0)
        signal += scatter * spread
    if photons:
        signal = rng.poisson(signal * photons) / photons
    if crosstalk:
        kernel = np.array([crosstalk, 1 - 2 * crosstalk, crosstalk])
        signal = ndimage.convolve1d(signal, kernel, axis=1, mode="nearest")
    if ring:
        gain = 1 + ring * rng.standard_normal(geom.n_det)
        bad = rng.choice(geom.n_det, 3, replace=False)
        gain[bad] += 10 * ring * rng.choice([-1, 1], 3)  # a few drifting channels
        signal = signal * gain[None, :]
    floor = 1.0 / photons if photons else 1e-12
    sino = -np.log(np.maximum(signal, floor))
    return (fan_fbp(sino, geom) / cm).astype(np.float32)


def make_fan_phantom(part="inserts", size=256, seed=None, supersample=4, kvp=150.0,
                     filters_mm=None, energy_kev=None, photons=2e5, scatter=0.01, ring=0.003,
                     crosstalk=0.25, clip8=False, pixel_mm=None, n_views=None, **layout):
    """A fan-beam CT slice of a part, with its truth.

    Parameters
    ----------
    part : str
        ``"inserts"`` (3-5 steel/copper/titanium discs, one a sleeve in an air gap, in an
        aluminium plate; ``plate="polymer"`` and ``metals=(...)`` change them),
        ``"ceramic"`` (PEEK body, alumina ring and balls) or ``"composite"`` (carbon-fibre
        lap joint, titanium fastener, aluminium strip; ``fastener="steel"``).
    size : int
        Image side, px (256 and 512 take about 1 and 4 s).
    seed : int, optional
        Layout, noise and gains (None: 0); the same seed gives the same slice.
    supersample : int
        Sub-pixels per pixel side of ``truth_hr``.
    kvp : float
        Tube voltage, 120-160 kV typical (:func:`ctseg.xray_spectra.tungsten_spectrum`).
    filters_mm : dict, optional
        Pre-filters (default 1 mm aluminium, 1 mm copper).
    energy_kev : float, optional
        A monochromatic scan at this energy instead (no beam hardening).
    photons : float
        Photons per channel and view in the open beam; 0: no noise.
    scatter, ring, crosstalk : float
        See :func:`simulate_fan_ct`; 0 turns each off.
    clip8 : bool or (lo, hi)
        8-bit export: the image becomes uint8, 0 at ``lo`` and 255 at ``hi`` (1/cm).
        True picks lo = 0 and hi = the 25th percentile of the densest material's
        reconstruction, so that most of it saturates.
    pixel_mm : float, optional
        Default 60 mm / size.
    n_views : int, optional
    **layout
        Material choices of the part (see :func:`part_scene`).

    Returns
    -------
    FanPhantom

    Example
    -------
    >>> p = make_fan_phantom("ceramic", size=32, n_views=48, supersample=2)
    >>> p.names, p.image.shape, p.truth_hr.shape
    (('air', 'peek', 'alumina'), (32, 32), (64, 64))
    """
    seed = 0 if seed is None else int(seed)
    pixel_mm = 60.0 / size if pixel_mm is None else float(pixel_mm)
    named = part_scene(part, size, seed, **layout)
    if energy_kev is not None:
        energies, weights = np.array([float(energy_kev)]), np.array([1.0])
    else:
        energies, weights = tungsten_spectrum(kvp, filters_mm)
    present = sorted(set(named.label) | {"air"})
    names = tuple(sorted(present, key=lambda m: effective_attenuation(m, energies, weights, 0.3)))
    scene = named.numbered(list(names))
    # an energy-integrating detector weighs each photon by its energy
    w = weights * energies / (weights @ energies)
    mu = np.array([linear_attenuation(m, energies) for m in names])
    img = simulate_fan_ct(scene, len(names), (w, mu), size, pixel_mm, photons=photons,
                          scatter=scatter, ring=ring, crosstalk=crosstalk, n_views=n_views,
                          seed=seed + 1)
    hr = scene.paint(size, supersample)
    frac = np.stack([(hr == k).reshape(size, supersample, size, supersample).mean(axis=(1, 3))
                     for k in range(len(names))])
    truth = np.argmax(frac, axis=0).astype(np.uint8)
    window = None
    if clip8 is not False:
        lo, hi = (0.0, float(np.percentile(img[truth == len(names) - 1], 25))) \
            if clip8 is True else map(float, clip8)
        window = (lo, hi)
        img = np.round(np.clip((img - lo) / (hi - lo), 0, 1) * 255).astype(np.uint8)
    settings = {"part": part, "seed": seed, "kvp": kvp, "energy_kev": energy_kev,
                "photons": photons, "scatter": scatter, "ring": ring, "crosstalk": crosstalk,
                "layout": layout}
    return FanPhantom(image=img, truth=truth, truth_hr=hr, supersample=supersample, names=names,
                      pixel_mm=pixel_mm, window=window, settings=settings)
