"""True 3D phantoms with known truth (tests and benchmarks of the 3D mode).

Independent of the slice simulator of :mod:`ctseg.phantoms`: the part is a set of analytic
signed-distance shapes in physical coordinates (index x spacing), tilted as a whole by a
random rotation per seed and painted in order (a later shape wins). Each voxel is sampled
at ``supersample**3`` points; the image is the materials' grays mixed by those volume
fractions (partial volume), blurred by a 3D Gaussian, plus Gaussian noise. The truth of a
voxel is its majority material; :func:`interface_distance` measures how far points lie
from the true interface between two materials.
"""
from dataclasses import dataclass, field

import numpy as np
from scipy import ndimage
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from .errors import ParameterError

MATERIALS = ("air", "polymer", "aluminium", "steel")
GRAY = {"air": 0.0, "polymer": 0.25, "aluminium": 0.62, "steel": 2.5}
"""Gray of each material (about 1/cm at 100 keV); steel is 10x the polymer's contrast."""
POLYMER_SD = 4.0
"""Default noise: the polymer's gray is this many noise sd above air."""
BISECT_STEPS = 12
"""Bisection steps that put each interface sample on the analytic interface (cell/4096)."""
NEIGHBOURS = 8
"""Interface samples that fit the local tangent plane in :func:`interface_distance`."""
FLATNESS = 0.1
"""Smallest / middle eigenvalue below which the samples around a point count as a plane."""
PLANE_RANGE = 3.0
"""Voxels from the interface within which :func:`interface_distance` uses the tangent plane."""
CHUNK_POINTS = 2 ** 21  # supersampled points labelled at once (memory bound)


def _sdf(kind, prm, p):
    """Signed distance (negative inside) of a shape at local points ``p`` (n, 3)."""
    if kind == "sphere":
        c, r = prm
        return np.linalg.norm(p - c, axis=1) - r
    if kind == "box":  # centre, half sizes, edge rounding
        c, b, r = prm
        q = np.abs(p - c) - (np.asarray(b) - r)
        return np.linalg.norm(np.maximum(q, 0.0), axis=1) + np.minimum(q.max(axis=1), 0.0) - r
    # cylinder along w: centre, radius, half height, rounding (a tube: and inner radius)
    c, radius, half, r = prm[:4]
    rho = np.hypot(p[:, 0] - c[0], p[:, 1] - c[1])
    d = np.column_stack([rho - (radius - r), np.abs(p[:, 2] - c[2]) - (half - r)])
    out = np.linalg.norm(np.maximum(d, 0.0), axis=1) + np.minimum(d.max(axis=1), 0.0) - r
    return np.maximum(out, prm[4] - rho) if kind == "tube" else out


def _bound(kind, prm):
    """Centre and radius of a ball holding the shape."""
    c = np.asarray(prm[0], float)
    if kind == "sphere":
        return c, prm[1]
    return c, float(np.linalg.norm(prm[1]) if kind == "box" else np.hypot(prm[1], prm[2]))


@dataclass
class Scene:
    """Shapes painted in order in the part's frame: local = (x - centre) @ rotation.

    ``shapes`` holds (label, kind, params) with kind 'box', 'cylinder', 'sphere' or
    'tube' (a cylinder with a cylindrical hole: params of the outer cylinder plus the
    inner radius), label the material painted inside."""

    centre: np.ndarray
    rotation: np.ndarray
    shapes: list
    background: int = 0

    def labels_at(self, points):
        """Material label at each physical point (n, 3) -> (n,) uint8."""
        pts = np.asarray(points, float).reshape(-1, 3)
        local = (pts - self.centre) @ self.rotation
        out = np.full(len(pts), self.background, np.uint8)
        for label, kind, prm in self.shapes:
            c, r = _bound(kind, prm)
            sel = np.flatnonzero(np.einsum("ij,ij->i", local - c, local - c) <= r * r)
            out[sel[_sdf(kind, prm, local[sel]) < 0]] = label
        return out


@dataclass
class Phantom3D:
    """A simulated volume with its truth.

    Attributes
    ----------
    image, truth : (nz, ny, nx) float32 and uint8 ndarrays; truth: each voxel's majority
        material (ties: the lower label)
    names : tuple of str, material of each label (ascending gray)
    gray : (K,) float ndarray, noise-free gray of each label
    spacing : (3,) float ndarray, voxel size along x, y, z
    supersample : int, samples per voxel along each axis
    labels_hr : (nz*s, ny*s, nx*s) uint8 ndarray, label at each sample
    fractions : (K, nz, ny, nx) float32 ndarray or None, volume fraction of each label
    scene : Scene, the analytic shapes (``scene.labels_at`` labels any point)
    noise_sd, blur_vox : float
    features : dict, what was placed (housing kind, fin thickness, pores, rotation...)
    """

    image: np.ndarray
    truth: np.ndarray
    names: tuple
    gray: np.ndarray
    spacing: np.ndarray
    supersample: int
    labels_hr: np.ndarray
    fractions: object
    scene: Scene
    noise_sd: float
    blur_vox: float
    features: dict = field(default_factory=dict)
    _interfaces: dict = field(default_factory=dict, repr=False)

    @property
    def voxel(self):
        """Length of one voxel for distances: the smallest spacing."""
        return float(self.spacing.min())

    def sample_coordinates(self, axis):
        """Physical coordinate of each supersampled cell centre along axis 0 (x), 1, 2."""
        n, s = self.labels_hr.shape[2 - axis], self.supersample
        return ((np.arange(n) + 0.5) / s - 0.5) * self.spacing[axis]


def _code(name, materials):
    """Label of ``name``, or of the closest present material in gray order (denser first)."""
    i = MATERIALS.index(name)
    j = min((MATERIALS.index(m) for m in materials), key=lambda j: (abs(j - i), -j))
    return list(materials).index(MATERIALS[j])


def _render(scene, shape, spacing, names, gray, supersample, blur_vox, noise_sd, rng,
            keep_fractions, features):
    """The phantom of a scene: supersampled labels, fractions, truth and image."""
    nz, ny, nx = shape
    s = int(supersample)
    K = len(gray)
    hr = np.empty((nz * s, ny * s, nx * s), np.uint8)
    frac = np.empty((K, nz, ny, nx), np.float32)
    coords = [((np.arange(n * s) + 0.5) / s - 0.5) * spacing[a] for a, n in enumerate((nx, ny, nz))]
    X, Y = np.meshgrid(coords[0], coords[1])
    step, per_slice = max(1, CHUNK_POINTS // (X.size * s)), X.size  # voxel slices per chunk
    for k0 in range(0, nz, step):
        k1 = min(nz, k0 + step)
        zs = coords[2][k0 * s:k1 * s]
        pts = np.column_stack([np.tile(X.ravel(), len(zs)), np.tile(Y.ravel(), len(zs)),
                               np.repeat(zs, per_slice)])
        lab = scene.labels_at(pts).reshape(len(zs), ny * s, nx * s)
        hr[k0 * s:k1 * s] = lab
        blocks = lab.reshape(k1 - k0, s, ny, s, nx, s)
        for m in range(K):
            frac[m, k0:k1] = (blocks == m).mean(axis=(1, 3, 5))
    truth = np.argmax(frac, axis=0).astype(np.uint8)
    clean = np.tensordot(np.asarray(gray, np.float32), frac, axes=1)
    sigma = [blur_vox * float(np.min(spacing)) / spacing[a] for a in (2, 1, 0)]  # z, y, x
    image = ndimage.gaussian_filter(clean, sigma, mode="nearest") if blur_vox > 0 else clean
    image = (image + noise_sd * rng.standard_normal(shape).astype(np.float32)).astype(np.float32)
    return Phantom3D(image=image, truth=truth, names=tuple(names), gray=np.asarray(gray, float),
                     spacing=spacing, supersample=s, labels_hr=hr,
                     fractions=frac if keep_fractions else None, scene=scene,
                     noise_sd=float(noise_sd), blur_vox=float(blur_vox), features=features)


def _grid_shape(size, spacing):
    """Voxels along z, y, x of a physical cube ``size`` smallest spacings across."""
    h = float(np.min(spacing))
    return tuple(max(8, int(round(size * h / spacing[a]))) for a in (2, 1, 0))


def _check_materials(materials):
    """The material names, checked: known, distinct, in ascending gray order."""
    names = tuple(materials)
    if not names or any(m not in GRAY for m in names) or len(set(names)) != len(names) \
            or list(names) != sorted(names, key=MATERIALS.index):
        raise ParameterError(f"materials: expected distinct names among {MATERIALS}, in that "
                             f"order, got {materials!r}")
    return names


def make_part_3d(size=96, seed=0, spacing=(1.0, 1.0, 1.0), blur_vox=0.9, noise_sd=None,
                 supersample=2, materials=MATERIALS, housing="auto", fin_vox=2.5,
                 porosity=True, keep_fractions=True):
    """A tilted multi-material part in a volume, with its truth.

    In the part's frame (u, v, w), h the smallest spacing: an aluminium housing (a rounded
    box, or a rounded cylinder; 'auto' alternates by seed) with a bore along w lined by a
    polymer bushing standing out of the top, a polymer layer 3.5-5 h thick under the
    bottom, a steel shaft in an air gap of 2.5-3.5 h standing out at both ends, a steel
    ball standing out of the housing wall, an aluminium fin ``fin_vox`` h thick, up to 6-10
    spherical gas pores of radius 2-4 h inside the aluminium (as many as fit with 1.5 h
    of it all round), and air around. The part is turned by a random rotation of the seed
    and scaled to fill the box but for about 3 h + blur of air (``features`` has both).

    Parameters
    ----------
    size : int
        Voxels along the axis of the smallest spacing; the box is a physical cube
        (``round(size * h / spacing)`` voxels along each axis, at least 8).
    seed : int
        Sets the shapes, the rotation and the noise.
    spacing : (3,) floats
        Voxel size along x, y, z.
    blur_vox : float
        Gaussian blur sigma in units of h (0: none).
    noise_sd : float, optional
        Gaussian noise sd; default the polymer's gray / :data:`POLYMER_SD`.
    supersample : int
        Samples per voxel along each axis for the volume fractions.
    materials : tuple of str
        Materials present, in ascending gray order; the shapes of an absent one take the
        closest present material (the denser one first).
    housing : {'auto', 'box', 'cylinder'}
    fin_vox, porosity : float, bool
    keep_fractions : bool
        Keep the per-material volume fractions (K float32 volumes).

    Returns
    -------
    Phantom3D

    Example
    -------
    >>> ph = make_part_3d(24, seed=1, porosity=False)
    >>> ph.image.shape, ph.image.dtype.name, ph.truth.dtype.name, ph.names[3]
    ((24, 24, 24), 'float32', 'uint8', 'steel')
    """
    names = _check_materials(materials)
    if housing not in ("auto", "box", "cylinder"):
        raise ParameterError(f"housing: expected 'auto', 'box' or 'cylinder', got {housing!r}")
    sp = np.asarray(spacing, float).reshape(3)
    shape = _grid_shape(size, sp)
    rng = np.random.default_rng(seed)
    h = float(sp.min())
    extent = (np.array(shape[::-1]) - 1.0) * sp
    kind = housing if housing != "auto" else ("box" if seed % 2 == 0 else "cylinder")
    al, po, st, air = (_code(m, names) for m in ("aluminium", "polymer", "steel", "air"))
    quat = rng.standard_normal(4)
    rot = Rotation.from_quat(quat / np.linalg.norm(quat)).as_matrix()
    # sizes in units of the part's scale S, chosen below so that the tilted part fits
    hz, hx, r_shaft, r_ball, fin_len, shaft_c = rng.uniform(0.95, 1.05, 6) * (0.2, 0.25, 0.07, 0.06, 0.08, 0.02)
    hy = 0.88 * hx if kind == "box" else hx
    shaft_c *= rng.choice([-1.0, 1.0])
    ball_c = np.array([-hx + 0.3 * r_ball, -0.35 * hy, 0.05])
    key = np.array([[u, v, w] for u in (-hx, hx) for v in (-hy, hy) for w in (-hz, hz + 0.04)]
                   + [[hx + fin_len, v, 0.05] for v in (-0.08, 0.12)]
                   + [[u, v, shaft_c + w * (hz + 0.10)] for u in (-r_shaft, r_shaft)
                      for v in (-r_shaft, r_shaft) for w in (-1, 1)]
                   + [ball_c + np.array(d) * r_ball for d in np.eye(3).tolist() + (-np.eye(3)).tolist()])
    t_cap, gap = rng.uniform(3.5, 5.0) * h, rng.uniform(2.5, 3.5) * h
    centre = extent / 2 + rng.uniform(-0.02, 0.02, 3) * extent
    room = np.min(extent / 2 - np.abs(centre - extent / 2)) - 3 * h - blur_vox * h - t_cap
    S = room / np.abs(key @ rot.T).max()
    hx, hy, hz, r_shaft, r_ball, fin_len, shaft_c = (v * S for v in (hx, hy, hz, r_shaft, r_ball,
                                                                    fin_len, shaft_c))
    c_cap = (0.0, 0.0, -hz - t_cap / 2 + 0.01 * h)  # overlaps the housing a little
    if kind == "box":
        body = (al, "box", ((0, 0, 0), (hx, hy, hz), 0.03 * S))
        cap = (po, "box", (c_cap, (0.8 * hx, 0.8 * hy, t_cap / 2), 0.0))
    else:
        body = (al, "cylinder", ((0, 0, 0), hx, hz, 0.03 * S))
        cap = (po, "cylinder", (c_cap, 0.8 * hx, t_cap / 2, 0.0))
    r_in = r_shaft + gap
    r_bush = r_in + max(0.045 * S, 3.5 * h)
    bottom, top = -hz - t_cap, hz + 0.04 * S
    fin = (al, "box", ((hx + fin_len / 2 - 0.02 * S, 0.02 * S, 0.05 * S),
                       (fin_len / 2 + 0.02 * S, 0.10 * S, fin_vox * h / 2), 0.0))
    shapes = [body, fin, cap,
              (air, "cylinder", ((0, 0, (bottom + top) / 2), r_in, (top - bottom) / 2 + h, 0.0)),
              (po, "tube", ((0, 0, (bottom + top) / 2), r_bush, (top - bottom) / 2, 0.0, r_in)),
              (st, "cylinder", ((0, 0, shaft_c), r_shaft, hz + 0.10 * S, 0.0)),
              (st, "sphere", (ball_c * S, r_ball))]
    scene = Scene(centre=centre, rotation=rot, shapes=shapes, background=air)
    pores = _place_pores(scene, rng, h, (hx, hy, hz), al, air) if porosity else []
    scene.shapes += [(air, "sphere", (c, r)) for c, r in pores]
    sd = GRAY["polymer"] / POLYMER_SD if noise_sd is None else float(noise_sd)
    gray = np.array([GRAY[m] for m in names])
    features = {"housing": kind, "scale": S / h, "fin_vox": float(fin_vox), "air_gap_vox": gap / h,
                "polymer_layer_vox": t_cap / h, "pores": [(c.tolist(), r / h) for c, r in pores],
                "rotation": rot.tolist(), "centre": centre.tolist(),
                "shapes": ["housing", "fin", "polymer layer", "bore", "bushing", "shaft", "ball"]
                + ["pore"] * len(pores)}  # the name of each of scene.shapes
    return _render(scene, shape, sp, names, gray, supersample, blur_vox, sd, rng,
                   keep_fractions, features)


def _place_pores(scene, rng, h, half, al, air, tries=2000):
    """Centres (local frame) and radii of pores with 1.5 h of aluminium all round."""
    corners = np.array(np.meshgrid(*[[-1, 1]] * 3)).reshape(3, -1).T / 3 ** 0.5
    dirs = np.vstack([[0, 0, 0], np.eye(3), -np.eye(3), corners])
    want, pores = int(rng.integers(6, 11)), []
    c = rng.uniform(-1.0, 1.0, (tries, 3)) * np.asarray(half)
    r = rng.uniform(2.0, 4.0 - 2.0 * np.arange(tries) / tries) * h  # shrinking: thin walls get pores too
    probe = c[:, None] + (r + 1.5 * h)[:, None, None] * np.vstack([dirs, 0.5 * dirs[1:]])[None]
    ok = (scene.labels_at(probe.reshape(-1, 3) @ scene.rotation.T + scene.centre) == al).reshape(tries, -1)
    for i in np.flatnonzero(ok.all(axis=1) & (al != air)):
        if len(pores) < want and all(np.linalg.norm(c[i] - c2) >= r[i] + r2 + 2 * h for c2, r2 in pores):
            pores.append((c[i], float(r[i])))
    return pores


def make_sphere_3d(size=32, radius=9.3, centre=None, spacing=(1.0, 1.0, 1.0), blur_vox=0.9,
                   noise_sd=0.0, supersample=2):
    """One sphere of material 1 (gray 1) in air, for checks against an analytic surface.

    ``centre`` (physical x, y, z) defaults to a point off the voxel grid near the middle.

    Example
    -------
    >>> ph = make_sphere_3d(16, radius=5.0)
    >>> int(ph.truth.sum()) in range(480, 570)  # 4/3 pi 5^3 = 524 voxels
    True
    """
    sp = np.asarray(spacing, float).reshape(3)
    shape = _grid_shape(size, sp)
    extent = (np.array(shape[::-1]) - 1.0) * sp
    c = extent / 2 + 0.237 * sp if centre is None else np.asarray(centre, float)
    scene = Scene(centre=c, rotation=np.eye(3), shapes=[(1, "sphere", ((0, 0, 0), radius))])
    return _render(scene, shape, sp, ("air", "sphere"), (0.0, 1.0), supersample, blur_vox,
                   noise_sd, np.random.default_rng(0), True,
                   {"centre": c.tolist(), "radius": float(radius)})


def interface_points(phantom, a, b):
    """Points (n, 3, physical) on the true interface between labels ``a`` and ``b``.

    One point per face between neighbouring supersampled cells of labels a and b: the
    crossing of the segment between the two cell centres with the analytic interface,
    found by :data:`BISECT_STEPS` bisection steps on ``scene.labels_at``; so the points lie
    on the interface (to 1/4096 of a cell), about one per (voxel / supersample)^2 of it.
    Cached on the phantom. Empty (0, 3) when the two never touch.
    """
    key = (min(a, b), max(a, b))
    if key in phantom._interfaces:
        return phantom._interfaces[key]
    lab, s = phantom.labels_hr, phantom.supersample
    coords = [phantom.sample_coordinates(ax) for ax in (0, 1, 2)]
    starts, ends = [], []
    for ax in range(3):  # numpy axis ax is physical axis 2 - ax
        l0, l1 = lab[(slice(None),) * ax + (slice(0, -1),)], lab[(slice(None),) * ax + (slice(1, None),)]
        idx = np.argwhere(((l0 == a) & (l1 == b)) | ((l0 == b) & (l1 == a)))
        starts.append(np.column_stack([coords[0][idx[:, 2]], coords[1][idx[:, 1]], coords[2][idx[:, 0]]]))
        ends.append(starts[-1] + np.eye(3)[2 - ax] * phantom.spacing[2 - ax] / s)
    p0, p1 = np.vstack(starts), np.vstack(ends)
    first = phantom.scene.labels_at(p0)
    for _ in range(BISECT_STEPS):
        mid = 0.5 * (p0 + p1)
        same = phantom.scene.labels_at(mid) == first
        p0[same] = mid[same]
        p1[~same] = mid[~same]
    pts = 0.5 * (p0 + p1)
    phantom._interfaces[key] = pts
    return pts


def interface_distance(phantom, points, a, b):
    """Distance in voxels (the smallest spacing) from each point to the true interface
    between labels ``a`` and ``b``.

    The interface is sampled by :func:`interface_points`. Within :data:`PLANE_RANGE`
    voxels of the nearest sample, the distance is to the tangent plane through it, fitted
    to its :data:`NEIGHBOURS` nearest samples where those are flat (:data:`FLATNESS`);
    elsewhere the distance to the nearest sample. Accuracy, against the analytic distance
    to spheres of radius 2.6-9.3 voxels, points within 3 voxels: mean error 0.003-0.01
    voxel and at most 0.06 at supersample 2, 0.02 at 3, 0.11 at 1 (tested); at edges and
    corners (samples not flat) the nearest sample over-estimates by up to the sample
    spacing, about 0.7 / supersample voxel. ``inf`` everywhere when a and b never touch.

    Example
    -------
    >>> ph = make_sphere_3d(16, radius=5.0)
    >>> c = np.array(ph.features["centre"])
    >>> d = interface_distance(ph, [c + [5.3, 0, 0], c + [0, 0, -4.0]], 0, 1)
    >>> np.round(d, 1).tolist()
    [0.3, 1.0]
    """
    q = np.asarray(points, float).reshape(-1, 3)
    P = interface_points(phantom, a, b)
    if len(P) == 0 or len(q) == 0:
        return np.full(len(q), np.inf)
    k = min(NEIGHBOURS, len(P))
    d, idx = cKDTree(P).query(q, k=k)
    d, idx = d.reshape(len(q), k), idx.reshape(len(q), k)
    out = d[:, 0].copy()
    near = np.flatnonzero(d[:, 0] <= PLANE_RANGE * phantom.voxel)
    if len(near) and k >= 3:
        nb = P[idx[near]]
        dev = nb - nb.mean(axis=1, keepdims=True)
        w, v = np.linalg.eigh(np.einsum("nki,nkj->nij", dev, dev))
        flat = w[:, 0] <= FLATNESS * np.maximum(w[:, 1], 1e-300)
        normal = v[:, :, 0]
        plane = np.abs(np.einsum("ni,ni->n", q[near] - nb[:, 0], normal))
        out[near[flat]] = plane[flat]
    return out / phantom.voxel
