"""Fan-beam CT geometry: exact line integrals of analytic shapes and fan-beam FBP.

Used by :mod:`ctseg.phantoms_fan`. Deliberately unlike :mod:`ctseg.projection` (pixel
driven, parallel beam) and :mod:`ctseg.phantoms` (bilinear samples of a fraction map): a
part is a list of convex shapes (ellipses and convex polygons) painted in order, later
over earlier, and each ray's path length through every material is exact: the chord of
each shape is solved in closed form (a quadratic for an ellipse, Cyrus-Beck clipping for
a polygon) and the painting order is resolved along the ray.

Geometry (all lengths in pixels of the reconstructed image, pixel (r, c) centred at
x = c, y = r): the source circles the isocentre (the image centre) at distance ``sod``;
a flat detector of ``n_det`` channels stands ``sdd`` from the source, perpendicular to
the central ray; 360 degrees of views. Reconstruction is the weighted fan-beam FBP for a
flat detector (Kak and Slaney, "Principles of Computerized Tomographic Imaging", 1988,
section 3.4.2): pre-weighting by D / sqrt(D^2 + s^2), a Hann-windowed ramp filter on the
detector rescaled to the isocentre, and back-projection weighted by 1 / U^2.
"""
from dataclasses import dataclass

import numpy as np
from numba import njit

ELLIPSE, POLYGON = 0, 1
MAX_SIDES = 16


class Scene:
    """Convex shapes painted in order (a later shape covers an earlier one), each with a
    material label; coordinates in pixels of the image (x = column, y = row).

    Example
    -------
    >>> sc = Scene()
    >>> sc.disc(10.0, 10.0, 5.0, 1); sc.box(10.0, 10.0, 2.0, 1.0, 0.0, 0)
    >>> lab = sc.paint(20, 2)
    >>> lab.shape, int(lab[20, 20]), int(lab[20, 12])
    ((40, 40), 0, 1)
    """

    def __init__(self):
        self.kind, self.label, self.ellipse_par, self.sides, self.bound = [], [], [], [], []

    def ellipse(self, cx, cy, a, b, angle, label):
        """An ellipse of semi-axes ``a`` (along ``angle``, radians) and ``b``."""
        self.kind.append(ELLIPSE)
        self.label.append(int(label))
        self.ellipse_par.append((cx, cy, a, b, angle))
        self.sides.append(np.zeros((0, 3)))
        self.bound.append((cx, cy, max(a, b)))

    def disc(self, cx, cy, r, label):
        """A disc of radius ``r``."""
        self.ellipse(cx, cy, r, r, 0.0, label)

    def polygon(self, vertices, label):
        """A convex polygon, vertices in either order."""
        v = np.asarray(vertices, float)
        area2 = np.sum(v[:, 0] * np.roll(v[:, 1], -1) - np.roll(v[:, 0], -1) * v[:, 1])
        if area2 < 0:
            v = v[::-1]
        d = np.roll(v, -1, axis=0) - v
        normal = np.column_stack([d[:, 1], -d[:, 0]]) / np.hypot(d[:, 0], d[:, 1])[:, None]
        # inside: n . x <= c for every side (outward normals of a counter-clockwise polygon)
        self.kind.append(POLYGON)
        self.label.append(int(label))
        self.ellipse_par.append((0.0,) * 5)
        self.sides.append(np.column_stack([normal, np.sum(normal * v, axis=1)]))
        centre = v.mean(axis=0)
        self.bound.append((centre[0], centre[1], float(np.max(np.hypot(*(v - centre).T)))))

    def box(self, cx, cy, hw, hh, angle, label):
        """A rectangle of half sides ``hw`` (along ``angle``) and ``hh``."""
        c, s = np.cos(angle), np.sin(angle)
        corners = [(-hw, -hh), (hw, -hh), (hw, hh), (-hw, hh)]
        self.polygon([(cx + u * c - v * s, cy + u * s + v * c) for u, v in corners], label)

    def arrays(self):
        """The shapes as arrays for :func:`path_lengths`."""
        k = len(self.kind)
        hp = np.zeros((k, MAX_SIDES, 3))
        n_sides = np.zeros(k, np.int64)
        for i, s in enumerate(self.sides):
            hp[i, :len(s)] = s
            n_sides[i] = len(s)
        return (np.array(self.kind, np.int64), np.array(self.label, np.int64),
                np.array(self.ellipse_par, float).reshape(k, 5), hp, n_sides,
                np.array(self.bound, float).reshape(k, 3))

    def inside(self, i, x, y):
        """Whether the points (x, y) lie in shape ``i``."""
        if self.kind[i] == ELLIPSE:
            cx, cy, a, b, ang = self.ellipse_par[i]
            c, s = np.cos(ang), np.sin(ang)
            u = ((x - cx) * c + (y - cy) * s) / a
            v = (-(x - cx) * s + (y - cy) * c) / b
            return u * u + v * v <= 1.0
        ok = np.ones(np.broadcast(x, y).shape, bool)
        for nx, ny, c in self.sides[i]:
            ok &= nx * x + ny * y <= c
        return ok

    def paint(self, size, supersample):
        """Labels at ``supersample`` sub-pixels per pixel side, (size*s, size*s) uint8."""
        n = size * supersample
        coords = (np.arange(n) + 0.5) / supersample - 0.5
        lab = np.zeros((n, n), np.uint8)
        for i in range(len(self.kind)):
            bx, by, br = self.bound[i]
            # only the sub-pixels of the bounding square are tested
            lo = np.searchsorted(coords, [bx - br - 1, by - br - 1])
            hi = np.searchsorted(coords, [bx + br + 1, by + br + 1])
            x, y = np.meshgrid(coords[lo[0]:hi[0]], coords[lo[1]:hi[1]])
            sub = lab[lo[1]:hi[1], lo[0]:hi[0]]
            sub[self.inside(i, x, y)] = self.label[i]
        return lab


@njit(cache=True)
def _lengths(ox, oy, ux, uy, kind, label, ell, hp, n_sides, bound, out):
    k = kind.shape[0]
    t0 = np.empty(k)
    t1 = np.empty(k)
    idx = np.empty(k, np.int64)
    for r in range(ox.shape[0]):
        m = 0
        for i in range(k):
            dx, dy = bound[i, 0] - ox[r], bound[i, 1] - oy[r]
            if abs(dx * uy[r] - dy * ux[r]) > bound[i, 2]:
                continue  # the ray misses the bounding circle
            if kind[i] == 0:
                c, s = np.cos(ell[i, 4]), np.sin(ell[i, 4])
                px, py = -dx, -dy
                qu = (px * c + py * s) / ell[i, 2]
                qv = (-px * s + py * c) / ell[i, 3]
                wu = (ux[r] * c + uy[r] * s) / ell[i, 2]
                wv = (-ux[r] * s + uy[r] * c) / ell[i, 3]
                a = wu * wu + wv * wv
                b = 2.0 * (qu * wu + qv * wv)
                cc = qu * qu + qv * qv - 1.0
                disc = b * b - 4.0 * a * cc
                if disc <= 0.0:
                    continue
                sq = np.sqrt(disc)
                lo, hi = (-b - sq) / (2.0 * a), (-b + sq) / (2.0 * a)
            else:
                lo, hi = -1e30, 1e30
                for j in range(n_sides[i]):
                    nu = hp[i, j, 0] * ux[r] + hp[i, j, 1] * uy[r]
                    rest = hp[i, j, 2] - hp[i, j, 0] * ox[r] - hp[i, j, 1] * oy[r]
                    if abs(nu) < 1e-15:
                        if rest < 0.0:
                            hi = lo - 1.0
                            break
                    elif nu > 0.0:
                        hi = min(hi, rest / nu)
                    else:
                        lo = max(lo, rest / nu)
                if hi <= lo:
                    continue
            t0[m], t1[m], idx[m] = lo, hi, i
            m += 1
        if m == 0:
            continue
        cuts = np.sort(np.concatenate((t0[:m], t1[:m])))
        for j in range(2 * m - 1):
            seg = cuts[j + 1] - cuts[j]
            if seg <= 0.0:
                continue
            mid = 0.5 * (cuts[j] + cuts[j + 1])
            top = -1
            for q in range(m):  # the last painted shape holding the segment wins
                if t0[q] <= mid <= t1[q] and idx[q] > top:
                    top = idx[q]
            if top >= 0:
                out[r, label[top]] += seg


def path_lengths(scene, origins, directions, n_labels):
    """Exact path length of each ray through each material of a scene.

    Parameters
    ----------
    scene : Scene
    origins, directions : (n, 2) array_like
        Ray start points (outside every shape) and unit directions, (x, y).
    n_labels : int

    Returns
    -------
    lengths : (n, n_labels) ndarray
        Pixel units; label 0's column counts only the shapes painted with label 0.

    Example
    -------
    >>> sc = Scene(); sc.disc(0.0, 0.0, 5.0, 1)
    >>> path_lengths(sc, [[-10.0, 3.0]], [[1.0, 0.0]], 2)
    array([[0., 8.]])
    """
    o = np.ascontiguousarray(origins, float).reshape(-1, 2)
    d = np.ascontiguousarray(directions, float).reshape(-1, 2)
    out = np.zeros((len(o), n_labels))
    if scene.kind:
        _lengths(o[:, 0].copy(), o[:, 1].copy(), d[:, 0].copy(), d[:, 1].copy(), *scene.arrays(), out)
    return out


@dataclass
class FanGeometry:
    """A flat-detector fan-beam scan over 360 degrees, lengths in image pixels.

    ``pitch`` is the channel spacing scaled to the isocentre (the detector's own is
    ``pitch * sdd / sod``); ``sub_rays`` the ray offsets across a channel, in pitches,
    whose intensities the channel averages (its finite width).
    """

    size: int
    n_views: int
    n_det: int
    sod: float
    sdd: float
    pitch: float
    sub_rays: tuple

    @property
    def centre(self):
        return (self.size - 1) / 2.0

    def view_angles(self):
        return np.arange(self.n_views) * (2 * np.pi / self.n_views)

    def channels(self):
        """Channel centres on the detector scaled to the isocentre (pixels)."""
        return (np.arange(self.n_det) - (self.n_det - 1) / 2.0) * self.pitch

    def rays(self, views):
        """Origins and unit directions (x, y) of the sub-rays of ``views``:
        two (len(views), n_det, len(sub_rays), 2) arrays."""
        beta = self.view_angles()[views]
        es = np.stack([np.cos(beta), np.sin(beta)], -1)[:, None, None, :]
        et = np.stack([-np.sin(beta), np.cos(beta)], -1)[:, None, None, :]
        s = (self.channels()[:, None] + np.asarray(self.sub_rays)[None, :] * self.pitch)
        s = s[None, :, :, None]
        src = self.centre + self.sod * es
        target = self.centre + s * et  # the ray's point on the isocentre line
        d = target - src
        d = d / np.linalg.norm(d, axis=-1, keepdims=True)
        return np.broadcast_to(src, d.shape), d


def fan_geometry(size, n_views=None, sod_factor=2.5, magnification=2.0, sub_rays=3):
    """A fan-beam geometry whose fan covers the whole square image.

    Parameters
    ----------
    size : int
        Image side (px).
    n_views : int, optional
        Views over 360 degrees; default twice the image side.
    sod_factor : float
        Source-to-isocentre distance in half image diagonals (2.5: a 47 degree fan).
    magnification : float
        Source-to-detector over source-to-isocentre distance.
    sub_rays : int
        Rays per channel across its width.

    Returns
    -------
    FanGeometry

    Example
    -------
    >>> g = fan_geometry(64)
    >>> g.n_views, g.n_det, round(g.sod, 1), round(g.sdd, 1)
    (128, 101, 113.1, 226.3)
    """
    r_fov = size / np.sqrt(2.0)
    sod = sod_factor * r_fov
    s_max = sod * np.tan(np.arcsin(r_fov / sod))  # edge of the fan at the isocentre
    n_det = 2 * int(np.ceil(s_max)) + 1
    offsets = tuple(((np.arange(sub_rays) + 0.5) / sub_rays - 0.5).tolist())
    return FanGeometry(size=int(size), n_views=int(n_views or 2 * size), n_det=n_det, sod=float(sod),
                       sdd=float(magnification * sod), pitch=1.0, sub_rays=offsets)


def _filter(proj, pitch, window):
    n_det = proj.shape[-1]
    pad = int(2 ** np.ceil(np.log2(2 * n_det)))
    k = np.fft.fftfreq(pad, 1.0 / pad)  # integer offsets in wrap order
    h = np.zeros(pad)
    h[0] = 1.0 / (4 * pitch * pitch)
    odd = (k % 2) == 1
    h[odd] = -1.0 / (np.pi * k[odd] * pitch) ** 2  # Ram-Lak kernel: no DC offset
    filt = np.fft.fft(h).real * pitch
    if window == "hann":
        filt *= 0.5 * (1 + np.cos(2 * np.pi * np.fft.fftfreq(pad)))
    return np.fft.ifft(np.fft.fft(proj, pad, axis=-1) * filt, axis=-1).real[..., :n_det]


@njit(cache=True)
def _backproject(q, cos_b, sin_b, sod, pitch, centre, ny, nx, out):
    n_det = q.shape[1]
    half = (n_det - 1) / 2.0
    for v in range(cos_b.shape[0]):
        cb, sb = cos_b[v], sin_b[v]
        for r in range(ny):
            y = r - centre
            for c in range(nx):
                x = c - centre
                a = x * cb + y * sb  # towards the source
                b = -x * sb + y * cb  # along the detector
                inv = sod / (sod - a)  # 1 / U, U the distance ratio of Kak and Slaney
                t = b * inv / pitch + half
                j = int(np.floor(t))
                if 0 <= j and j + 1 < n_det:
                    f = t - j
                    out[r, c] += (q[v, j] * (1.0 - f) + q[v, j + 1] * f) * (inv * inv)


def fan_fbp(sinogram, geom, window="hann"):
    """Fan-beam filtered back-projection onto the (size, size) image grid.

    Parameters
    ----------
    sinogram : (n_views, n_det) array_like
        Line integrals in pixel units, channels of ``geom`` (one value per channel).
    geom : FanGeometry
    window : {"hann", "ramp"}
        Apodisation of the ramp filter.

    Returns
    -------
    image : (size, size) float64 ndarray
        Attenuation per pixel.

    Example
    -------
    >>> g = fan_geometry(32, n_views=64)
    >>> fan_fbp(np.zeros((g.n_views, g.n_det)), g).shape
    (32, 32)
    """
    p = np.asarray(sinogram, float)
    s = geom.channels()
    weighted = p * (geom.sod / np.sqrt(geom.sod ** 2 + s ** 2))[None, :]
    q = _filter(weighted, geom.pitch, window)
    beta = geom.view_angles()
    out = np.zeros((geom.size, geom.size))
    _backproject(np.ascontiguousarray(q), np.cos(beta), np.sin(beta), geom.sod, geom.pitch,
                 geom.centre, geom.size, geom.size, out)
    # full scan: every ray is measured twice, hence half of the 2 pi / n_views step
    return out * (np.pi / geom.n_views)
