"""The box of the 3D CVT (:mod:`ctseg.cvt3d`): its faces and edges, the site classes that
keep sites on them, and the starting sites' classes with the added face and edge sites.

Private: :func:`ctseg.cvt3d.lloyd_cvt_3d` is the entry point.
"""
from itertools import product

import numpy as np

from ._cvt3d import _own_feature_sums_3d
from .errors import InputError

FREE, FACE, EDGE, CORNER = 0, 1, 2, 3
SITE_CLASSES = ("free", "face", "edge", "corner")
"""Names of the site classes, indexed by :attr:`CVT3DResult.site_class`."""


def box_features(n_xyz, sp):
    """Faces and edges of the box: their interior voxels (flat indices), the voxels'
    physical coordinates, and the fixed axes with their values.

    Returns ``{FACE: [...], EDGE: [...]}``, each a list in feature-number order of
    ``(idx, coords (m, 3), fixed_axes, fixed_values)``.
    """
    nx, ny, _ = n_xyz
    hi = (np.array(n_xyz) - 1) * sp
    out = {FACE: [], EDGE: []}
    for kind, n_fixed in ((FACE, 1), (EDGE, 2)):
        for axis in range(3):
            fixed = [axis] if kind == FACE else [b for b in range(3) if b != axis]
            for sides in product((0, 1), repeat=n_fixed):
                ranges = [np.arange(1, n - 1) for n in n_xyz]
                for b, side in zip(fixed, sides):
                    ranges[b] = np.array([side * (n_xyz[b] - 1)])
                ii, jj, kk = (g.ravel() for g in np.meshgrid(*ranges, indexing="ij"))
                order = np.argsort((kk * ny + jj) * nx + ii, kind="stable")
                ijk = np.column_stack([ii, jj, kk])[order]
                idx = (ijk[:, 2] * ny + ijk[:, 1]) * nx + ijk[:, 0]
                coords = ijk * sp
                values = [side * hi[b] for b, side in zip(fixed, sides)]
                out[kind].append((idx, coords, fixed, values))
    return out


def barycentres(features, labels, w, n):
    """Per feature: each region's rho weight on it (n,) and the rho-weighted barycentre of
    its voxels there (n, 3), exactly on the feature's plane or line."""
    result = []
    for idx, coords, fixed, values in features:
        sums = _own_feature_sums_3d(idx, coords, np.zeros(len(idx), np.int64), labels, w,
                                    np.zeros(n, np.int64), n)
        bw = sums[0]
        bary = (sums[1:4] / np.where(bw > 0, bw, 1.0)).T
        for b, v in zip(fixed, values):
            bary[:, b] = v
        result.append((bw, bary))
    return result


def start_sites(sites, labels_of, hi, feats, w):
    """Pin the corners, classify the starting sites and add the face and edge sites."""
    corners = np.array([[sx * hi[0], sy * hi[1], sz * hi[2]]
                        for sz, sy, sx in product((0, 1), repeat=3)])
    sites = sites.copy()
    n = len(sites)
    cls = np.full(n, FREE, np.int8)
    feat = np.full(n, -1, np.int64)
    for c, corner in enumerate(corners):
        d = np.sum((sites - corner) ** 2, axis=1)
        d[cls == CORNER] = np.inf
        k = int(np.argmin(d))
        sites[k], cls[k], feat[k] = corner, CORNER, c
    labels = labels_of(sites)
    new_sites, new_feat, new_cls = [], [], []
    # a new site lies on a face, so only a site on the box's surface can coincide with it
    taken = {tuple(p) for p in sites[np.any((sites == 0) | (sites == hi), axis=1)]}
    for kind in (EDGE, FACE):  # a site on an edge line is an edge site, not a face site
        bary = barycentres(feats[kind], labels, w, n)
        for f, ((_, _, fixed, values), (bw, b)) in enumerate(zip(feats[kind], bary)):
            on = np.all(sites[:, fixed] == values, axis=1)  # on the closed face or edge
            mine = on & (cls == FREE) & (bw > 0)
            sites[mine], cls[mine], feat[mine] = b[mine], kind, f
            add = (bw > 0) & ~on
            if not add.any() and not np.any((cls == kind) & (feat == f)) and bw.max() > 0:
                add = np.arange(n) == np.argmax(bw)  # only corners or edges reach it
            for k in np.flatnonzero(add):
                p = tuple(b[k])
                if p not in taken:
                    taken.add(p)
                    new_sites.append(b[k])
                    new_cls.append(kind)
                    new_feat.append(f)
    if new_sites:
        sites = np.vstack([sites, new_sites])
        cls = np.concatenate([cls, np.array(new_cls, np.int8)])
        feat = np.concatenate([feat, new_feat])
    if len(np.unique(sites, axis=0)) != len(sites):
        raise InputError("sites: two starting sites coincide after snapping to the box faces")
    return np.ascontiguousarray(sites), cls, feat


def border_voxels(features):
    """The flat indices and physical coordinates of every face and edge voxel (faces
    first, as ``features`` lists them)."""
    listed = [f for kind in (FACE, EDGE) for f in features[kind]]
    return np.concatenate([f[0] for f in listed]), np.concatenate([f[1] for f in listed])


def feature_tables(features, cls, feat):
    """What each Lloyd iteration needs to move the face and edge sites: the feature number
    of every face and edge voxel in :func:`border_voxels`'s order (faces 0-5, edges 6-17),
    each site's (-1: a free or corner site), and the axes its feature fixes with their
    values."""
    listed = [(kind, f, feature) for kind in (FACE, EDGE) for f, feature in enumerate(features[kind])]
    voxel_feature = np.repeat(np.arange(len(listed)), [len(feature[0]) for _, _, feature in listed])
    n = len(cls)
    site_feature = np.full(n, -1, np.int64)
    fixed_mask = np.zeros((n, 3), bool)
    fixed_value = np.zeros((n, 3))
    for g, (kind, f, (_, _, fixed, values)) in enumerate(listed):
        on = (cls == kind) & (feat == f)
        site_feature[on] = g
        fixed_mask[np.ix_(on, fixed)] = True
        fixed_value[np.ix_(on, fixed)] = values
    return voxel_feature, site_feature, fixed_mask, fixed_value
