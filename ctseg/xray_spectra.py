"""X-ray attenuation of engineering materials and a tungsten-anode tube spectrum.

Used by the fan-beam CT simulator (:mod:`ctseg.phantoms_fan`); independent of the
five-bin table of :mod:`ctseg.phantoms`.

Mass attenuation coefficients (total, with coherent scattering, cm^2/g) are approximate
values read from the NIST tables of Hubbell and Seltzer (NIST Standard Reference Database
126, "X-Ray Mass Attenuation Coefficients", which come from XCOM), rounded to three or
four digits, at ten energies from 15 to 200 keV; between them they are interpolated
log-log. Compounds and mixtures follow the mixture rule (mass-fraction weighted sum of the
elements). The densities are typical handbook values of the technical materials.

The tube spectrum is Kramers' law for a thick tungsten target (photon number per keV
proportional to (kVp - E) / E) plus the tungsten K lines (K-alpha 58-59 keV, K-beta
67 keV) above their 69.5 keV excitation edge, then filtered by the exit window and the
added filters with the same attenuation table.
"""
import numpy as np

TABLE_KEV = np.array([15.0, 20.0, 30.0, 40.0, 50.0, 60.0, 80.0, 100.0, 150.0, 200.0])
"""The energies of :data:`MASS_ATTENUATION` (keV)."""

MASS_ATTENUATION = {  # cm^2/g at TABLE_KEV (NIST SRD 126, approximate)
    "H": [0.3764, 0.3695, 0.3570, 0.3458, 0.3355, 0.3260, 0.3091, 0.2944, 0.2651, 0.2429],
    "C": [0.8071, 0.4420, 0.2562, 0.2076, 0.1871, 0.1753, 0.1610, 0.1514, 0.1347, 0.1229],
    "O": [1.690, 0.8651, 0.3779, 0.2585, 0.2132, 0.1907, 0.1678, 0.1551, 0.1361, 0.1237],
    "air": [1.614, 0.7779, 0.3538, 0.2485, 0.2080, 0.1875, 0.1662, 0.1541, 0.1356, 0.1233],
    "Al": [7.955, 3.441, 1.128, 0.5685, 0.3681, 0.2778, 0.2018, 0.1704, 0.1378, 0.1223],
    "Ti": [35.87, 15.85, 4.972, 2.214, 1.213, 0.7661, 0.4052, 0.2721, 0.1649, 0.1314],
    "Fe": [57.08, 25.68, 8.176, 3.629, 1.958, 1.205, 0.5952, 0.3717, 0.1964, 0.1460],
    "Cu": [74.05, 33.79, 10.92, 4.862, 2.613, 1.593, 0.7630, 0.4584, 0.2220, 0.1559],
}

# name: (density g/cm^3, {element: mass fraction}). Polymer is POM (CH2O); PEEK is
# C19H12O3; the carbon-fibre composite is 60 % fibre by volume in epoxy; alumina is a
# dense technical ceramic (Al2O3, 96 %, the rest taken as alumina too); steel is carbon
# steel (iron).
MATERIAL_DATA = {
    "air": (0.001205, {"air": 1.0}),
    "polymer": (1.41, {"C": 0.400, "H": 0.067, "O": 0.533}),
    "peek": (1.31, {"C": 0.792, "H": 0.042, "O": 0.166}),
    "cfrp": (1.58, {"C": 0.880, "H": 0.030, "O": 0.090}),
    "aluminium": (2.70, {"Al": 1.0}),
    "alumina": (3.85, {"Al": 0.529, "O": 0.471}),
    "titanium": (4.51, {"Ti": 1.0}),
    "steel": (7.85, {"Fe": 1.0}),
    "copper": (8.96, {"Cu": 1.0}),
}
"""Density and elemental composition by mass of every material the simulator knows."""

# the anode's K lines (keV) and their share of the photons at 150 kVp before filtration
_K_LINES = ((58.0, 0.35), (59.3, 0.45), (67.2, 0.20))
_K_EDGE_KEV = 69.5


def mass_attenuation(material, energies_kev):
    """Mass attenuation coefficient (cm^2/g) of a material or element at given energies.

    Parameters
    ----------
    material : str
        A key of :data:`MATERIAL_DATA` or of :data:`MASS_ATTENUATION`.
    energies_kev : array_like
        Photon energies, 15 to 200 keV (log-log interpolation between the table's).

    Returns
    -------
    mu_rho : ndarray, shape of ``energies_kev``

    Example
    -------
    >>> round(float(mass_attenuation("Fe", 60.0)), 3)
    1.205
    """
    e = np.asarray(energies_kev, float)
    if np.any(e < TABLE_KEV[0]) or np.any(e > TABLE_KEV[-1]):
        raise ValueError(f"energies must lie in {TABLE_KEV[0]}-{TABLE_KEV[-1]} keV")
    if material in MATERIAL_DATA:
        parts = MATERIAL_DATA[material][1].items()
    else:
        parts = ((material, 1.0),)
    log_e = np.log(TABLE_KEV)
    out = np.zeros_like(e)
    for element, w in parts:
        out += w * np.exp(np.interp(np.log(e), log_e, np.log(MASS_ATTENUATION[element])))
    return out


def linear_attenuation(material, energies_kev):
    """Linear attenuation coefficient (1/cm): mass attenuation times density.

    Parameters
    ----------
    material : str
        A key of :data:`MATERIAL_DATA`.
    energies_kev : array_like

    Returns
    -------
    mu : ndarray

    Example
    -------
    >>> round(float(linear_attenuation("aluminium", 100.0)), 3)
    0.46
    """
    return MATERIAL_DATA[material][0] * mass_attenuation(material, energies_kev)


def tungsten_spectrum(kvp=150.0, filters_mm=None, bin_kev=5.0):
    """Photon spectrum of a tungsten-anode tube behind its filters, in energy bins.

    Parameters
    ----------
    kvp : float
        Tube voltage, 40 to 200 kV.
    filters_mm : dict, optional
        Filter material (keys of :data:`MATERIAL_DATA`) to thickness in mm; default 1 mm
        aluminium (the exit window and the tube's own filtration) plus 1 mm copper, a usual
        industrial pre-filter at 150 kV.
    bin_kev : float
        Width of the energy bins; the first starts at 15 keV.

    Returns
    -------
    energies_kev : (n,) ndarray
        Bin centres.
    photons : (n,) ndarray
        Relative photon number per bin, summing to 1.

    Example
    -------
    >>> e, w = tungsten_spectrum(150.0)
    >>> 60 < float(e @ w) < 90, round(float(w.sum()), 6)
    (True, 1.0)
    """
    if filters_mm is None:
        filters_mm = {"aluminium": 1.0, "copper": 1.0}
    edges = np.arange(TABLE_KEV[0], kvp + 1e-9, bin_kev)
    e = 0.5 * (edges[:-1] + edges[1:])
    # Kramers' law integrated over each bin
    n = np.maximum(kvp - e, 0.0) / e * bin_kev
    if kvp > _K_EDGE_KEV:
        # line intensity grows as about (kVp/edge - 1)^1.6 (Green and Cosslett); 12 % of
        # the continuum at 150 kV
        share = 0.12 * ((kvp / _K_EDGE_KEV - 1.0) / (150.0 / _K_EDGE_KEV - 1.0)) ** 1.6
        for line, frac in _K_LINES:
            k = int(np.clip(np.searchsorted(edges, line) - 1, 0, len(e) - 1))
            n[k] += share * frac * n.sum()
    for name, mm in filters_mm.items():
        n = n * np.exp(-linear_attenuation(name, e) * mm / 10.0)
    return e, n / n.sum()


def effective_attenuation(material, energies_kev, photons, depth_cm=0.0):
    """Attenuation (1/cm) a material shows under a spectrum, energy-integrating detector.

    The spectrum is first hardened by ``depth_cm`` of the material itself; the value is the
    slope of -log(transmission) there, so materials can be put in the order the scanner sees.

    Parameters
    ----------
    material : str
    energies_kev, photons : (n,) array_like
        A spectrum, e.g. from :func:`tungsten_spectrum`.
    depth_cm : float

    Returns
    -------
    float

    Example
    -------
    >>> e, w = tungsten_spectrum(150.0)
    >>> mus = [effective_attenuation(m, e, w) for m in ("peek", "aluminium", "copper")]
    >>> bool(mus[0] < mus[1] < mus[2])
    True
    """
    e = np.asarray(energies_kev, float)
    w = np.asarray(photons, float) * e  # energy-integrating: each photon weighs its energy
    mu = linear_attenuation(material, e)
    d = 0.01
    t0 = w @ np.exp(-mu * depth_cm)
    t1 = w @ np.exp(-mu * (depth_cm + d))
    return float(np.log(t0 / t1) / d)
