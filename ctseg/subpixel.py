"""Sub-element placement of material boundaries (SPEC 10): vertices between two materials
moved to the ISO-50 crossing of the gray between their levels. One implementation for
triangles over a slice and tetrahedra over a volume: the dimension is the mesh's."""
import functools
from dataclasses import dataclass

import numpy as np
from scipy.ndimage import gaussian_filter, map_coordinates

from ._sets import unique_ints
from .errors import InputError, ParameterError
from .params import DEFAULTS
from .recursive_cut import order_by_gray
from .tetra_gray import VoxelOverlaps
from .tetrahedra import dihedral_angles, tetra_volumes
from .triangle_gray import triangle_gray
from .triangulation import triangle_areas

MIN_AREA_RATIO = 0.2
"""A move is refused when it leaves an incident element with less than this share of its
area (volume), or inverts it."""

BACKTRACK_STEPS = 4
"""A refused move is retried at half the shift, this many times."""

EDGE_PX = 2.0
"""The 3D mode's step check: a crossing counts only where the gray, within this many
voxels either side of it, comes within :data:`EDGE_SHARE` of the contrast of each level:
not a missed thin layer whose gray lies near the half-way, nor a feature too thin to reach
its level, whose ISO-50 lies inside it (README, Method: why 3D only)."""

EDGE_SHARE = 0.1
"""See :data:`EDGE_PX`."""


def material_levels_of_mesh(gray, area, material, interior, n_materials):
    """Each material's level: the area-weighted median gray of its triangles away from the
    boundary, or of all its triangles where those cover less than half its area (small
    parts: a few interior triangles there can be stray ones).

    Example
    -------
    >>> material_levels_of_mesh([1.0, 2.0, 9.0, 50.0], np.ones(4), [0, 0, 0, 1],
    ...                         [True, True, False, True], 2).tolist()
    [1.0, 50.0]
    """
    gray, area = np.asarray(gray, float), np.asarray(area, float)
    material, interior = np.asarray(material), np.asarray(interior, bool)
    levels = np.full(n_materials, np.nan)
    for k in range(n_materials):
        sel = (material == k) & interior
        if area[sel].sum() < 0.5 * area[material == k].sum():
            sel = material == k
        if sel.any():
            g, w = gray[sel], area[sel]
            o = np.argsort(g, kind="stable")
            cw = np.cumsum(w[o])
            levels[k] = g[o][np.searchsorted(cw, 0.5 * cw[-1])]
    return levels


def _vertex_materials(elements, material, n_points):
    """Per vertex: the lowest and highest material of its elements, and how many
    different ones (-1, -1, 0 for a vertex of no element)."""
    k = int(material.max()) + 1 if len(material) else 1
    # distinct (vertex, material) pairs as one sorted integer key each
    key = unique_ints(elements.ravel() * k + np.repeat(material, elements.shape[1]))
    vertex, mat = key // k, key % k
    count = np.bincount(vertex, minlength=n_points)
    lo = np.full(n_points, -1)
    hi = np.full(n_points, -1)
    first = np.searchsorted(vertex, np.arange(n_points))
    has = count > 0
    lo[has] = mat[first[has]]
    hi[has] = mat[first[has] + count[has] - 1]
    return lo, hi, count


def element_measures(points, elements):
    """Signed areas of triangles (points (n, 2)) or volumes of tetrahedra (points (n, 3))."""
    return (triangle_areas(points, elements) if points.shape[1] == 2
            else tetra_volumes(points, elements))


class _Quality:
    """What a move must keep of each element ``which`` (the others are never asked): at
    least :data:`MIN_AREA_RATIO` of its measure, and (tetrahedra, ``min_dihedral_deg`` > 0)
    a smallest dihedral angle of at least ``min_dihedral_deg`` or, below it, of its own."""

    def __init__(self, points, elements, min_dihedral_deg, which):
        self.measure0 = np.full(len(elements), np.nan)
        self.measure0[which] = element_measures(points, elements[which])
        self.angle0 = None
        if points.shape[1] == 3 and min_dihedral_deg:
            self.angle0 = np.full(len(elements), np.nan)
            self.angle0[which] = np.minimum(dihedral_angles(points, elements[which]).min(axis=1),
                                            min_dihedral_deg)

    def bad(self, points, elements, which):
        """Whether each element (``elements``, ``which`` their indices in the mesh) with
        vertices at ``points`` breaks the rule."""
        bad = element_measures(points, elements) < MIN_AREA_RATIO * self.measure0[which]
        if self.angle0 is not None:
            bad |= dihedral_angles(points, elements).min(axis=1) < self.angle0[which]
        return bad


def place_boundary_vertices(points, triangles, material, image, levels, *,
                            max_shift_fraction=DEFAULTS.subpixel_max_shift, smooth_px=0.0,
                            step_px=0.1, spacing=None, min_dihedral_deg=0.0, edge_px=0.0):
    """Move each vertex between exactly two materials to the ISO-50 crossing of the gray.

    For a vertex whose incident elements (triangles over a slice, or tetrahedra over a
    volume) hold exactly two materials a and b, the gray (smoothed by a Gaussian of
    ``smooth_px``, interpolated bilinearly, or trilinearly) is sampled every ``step_px``
    along the gradient direction through the vertex, up to ``max_shift_fraction`` of its
    shortest incident edge either way; the vertex moves to the crossing of
    ``(levels[a] + levels[b]) / 2`` nearest to it where the gray passes from a's side to
    b's; with ``edge_px`` > 0, only if within ``edge_px`` either side of it the gray comes
    within :data:`EDGE_SHARE` of the contrast of each level (the 3D mode's step check,
    :data:`EDGE_PX`). Vertices with one or three or more materials, vertices on the image
    border (the box's faces), and vertices with no such crossing in reach stay. A move
    that would invert an incident element, leave it with less than :data:`MIN_AREA_RATIO`
    of its area (volume), or (tetrahedra) make its smallest dihedral angle smaller than
    ``min_dihedral_deg`` and its own is retried at half the shift
    (:data:`BACKTRACK_STEPS` times), then dropped; moves that are each valid but together
    spoil an element are undone until none does. The labels do not change.

    Parameters
    ----------
    points : (n, 2) or (n, 3) array_like
        Vertices: (x, y) = (col, row) in pixel units over a slice; (x, y, z) = (i, j, k)
        index times ``spacing`` over a volume.
    triangles : (m, 3) or (m, 4) int array_like
        Positively oriented triangles (counter-clockwise) or tetrahedra.
    material : (m,) int array_like
        Material per element, 0..K-1.
    image : (rows, cols) or (nz, ny, nx) array_like
        The gray image or volume the labels were found on.
    levels : (K,) array_like
        Each material's gray level in the image's units (NaN: its vertices stay).
    max_shift_fraction : float
        Largest move as a share of the vertex's shortest incident edge, in (0, 1).
    smooth_px : float
        Gaussian smoothing of the image before sampling (0 = none), px (voxels of the
        finest axis).
    step_px : float
        Sampling step along the gradient, px (voxels of the finest axis).
    spacing : (3,) array_like, optional
        Voxel size (sx, sy, sz) of a volume (default 1); slices are in pixel units.
    min_dihedral_deg : float
        Tetrahedra only: the dihedral angle a move may not take an element below (0 = no
        check).
    edge_px : float
        Half-width of the step check, px (voxels of the finest axis; 0 = no check, the
        slices mode's choice).

    Returns
    -------
    moved : (n, d) float64 ndarray
        The vertices, boundary vertices moved.
    n_moved : int
        How many moved.

    Raises
    ------
    InputError
        Shapes that do not match.
    ParameterError
        ``max_shift_fraction`` outside (0, 1), negative ``smooth_px``, ``step_px`` <= 0,
        a bad ``spacing``.

    References
    ----------
    The ISO-50 rule of CT metrology surface determination (e.g. VDI/VDE 2630-1.2); SPEC 10.

    Example
    -------
    >>> img = np.where(np.arange(20)[None, :] < 9.7, 10.0, 90.0).repeat(20, 0)
    >>> pts = np.array([[0, 0], [19, 0], [19, 19], [0, 19], [9, 0], [9, 19], [9, 9.5]], float)
    >>> tri = np.array([[0, 4, 6], [4, 1, 6], [1, 2, 6], [2, 5, 6], [5, 3, 6], [3, 0, 6]])
    >>> mat = np.array([0, 1, 1, 1, 0, 0])
    >>> moved, n = place_boundary_vertices(pts, tri, mat, img, [10.0, 90.0], smooth_px=0)
    >>> n, round(float(moved[6, 0]), 2)
    (1, 9.5)
    """
    pts = np.asarray(points, float)
    tri = np.asarray(triangles, np.int64)
    mat = np.asarray(material, np.int64)
    img = np.asarray(image, float)
    lv = np.asarray(levels, float).ravel()
    dim = pts.shape[1] if pts.ndim == 2 else 0
    if dim not in (2, 3) or tri.ndim != 2 or tri.shape[1] != dim + 1:
        raise InputError(f"points (n, 2) and triangles (m, 3), or points (n, 3) and tetrahedra "
                         f"(m, 4) expected, got {pts.shape} and {tri.shape}")
    if mat.shape != (len(tri),) or img.ndim != dim:
        raise InputError(f"material: one per element ({len(tri)}) and a {dim}D image expected, "
                         f"got {mat.shape} and {img.shape}")
    if len(tri) and (mat.min() < 0 or mat.max() >= len(lv)):
        raise InputError(f"material: values must index levels (0..{len(lv) - 1})")
    if not 0.0 < max_shift_fraction < 1.0:
        raise ParameterError(f"max_shift_fraction: {max_shift_fraction!r} is not in (0, 1)")
    if smooth_px < 0 or step_px <= 0:
        raise ParameterError(f"smooth_px >= 0 and step_px > 0 needed, got {smooth_px!r}, {step_px!r}")
    sp = np.ones(dim) if spacing is None else np.asarray(spacing, float).ravel()
    if sp.shape != (dim,) or not np.all(np.isfinite(sp) & (sp > 0)):
        raise ParameterError(f"spacing: {dim} finite values > 0 expected, got {spacing!r}")
    moved = pts.copy()
    if len(tri) == 0 or len(lv) < 2:
        return moved, 0
    n = len(pts)
    lo, hi, count = _vertex_materials(tri, mat, n)
    border = (np.isclose(pts, pts.min(axis=0)) | np.isclose(pts, pts.max(axis=0))).any(axis=1)
    cand = np.flatnonzero((count == 2) & ~border)
    cand = cand[np.isfinite(lv[lo[cand]]) & np.isfinite(lv[hi[cand]]) & (lv[lo[cand]] != lv[hi[cand]])]
    if len(cand) == 0:
        return moved, 0
    # shortest incident edge per vertex (every edge of every element; repeats do not matter)
    pairs = [(i, j) for i in range(dim + 1) for j in range(i + 1, dim + 1)]
    e = np.concatenate([tri[:, list(ij)] for ij in pairs])
    elen = functools.reduce(np.hypot, (pts[e[:, 0]] - pts[e[:, 1]]).T)
    shortest = np.full(n, np.inf)
    np.minimum.at(shortest, e[:, 0], elen)
    np.minimum.at(shortest, e[:, 1], elen)
    h = float(sp.min())
    sigma = tuple(smooth_px * h / sp[::-1])  # per array axis: the same physical blur
    smooth = gaussian_filter(img, sigma, mode="nearest") if smooth_px > 0 else img

    def sample(values, xyz):  # (..., dim) physical points -> values, (bi/tri)linear
        idx = xyz.reshape(-1, dim) / sp
        return map_coordinates(values, idx[:, ::-1].T, order=1, mode="nearest").reshape(xyz.shape[:-1])

    p = pts[cand]
    # the gradient at the vertices, one axis at a time (a volume's three are large)
    g = np.column_stack([sample(np.gradient(smooth, sp[a], axis=dim - 1 - a), p) for a in range(dim)])
    gnorm = functools.reduce(np.hypot, g.T)
    ok = gnorm > 0
    cand, p, g, gnorm = cand[ok], p[ok], g[ok], gnorm[ok]
    if len(cand) == 0:
        return moved, 0
    la, lb = lv[lo[cand]], lv[hi[cand]]
    # +direction: from a's gray towards b's
    direction = g / gnorm[:, None] * np.sign(lb - la)[:, None]
    reach = max_shift_fraction * shortest[cand]
    step = step_px * h
    n_steps = int(np.ceil(reach.max() / step))
    unit = np.linspace(-1.0, 1.0, 2 * n_steps + 1)[None, :]
    shift = np.empty(len(cand))
    chunk = max(1, 4_000_000 // unit.size)  # profiles sampled in bounded chunks
    for c0 in range(0, len(cand), chunk):
        c = slice(c0, c0 + chunk)
        s = unit * reach[c, None]
        prof = sample(smooth, p[c, None, :] + s[:, :, None] * direction[c, None, :])
        f = (prof - 0.5 * (la[c] + lb[c])[:, None]) * np.sign(lb[c] - la[c])[:, None]
        up = (f[:, :-1] <= 0) & (f[:, 1:] > 0)
        denom = np.where(up, f[:, 1:] - f[:, :-1], 1.0)
        s_cross = s[:, :-1] + (-f[:, :-1] / denom) * (s[:, 1:] - s[:, :-1])
        s_cross = np.where(up, s_cross, np.inf)
        best = np.argmin(np.abs(s_cross), axis=1)
        shift[c] = s_cross[np.arange(len(s_cross)), best]
    found = np.isfinite(shift)
    if edge_px and found.any():
        # a crossing counts only on a step (EDGE_PX)
        at = np.flatnonzero(found)
        t = np.linspace(-1.0, 1.0, 2 * int(np.ceil(edge_px / step_px)) + 1) * edge_px * h
        chunk = max(1, 4_000_000 // t.size)
        for c0 in range(0, len(at), chunk):
            c = at[c0:c0 + chunk]
            q = p[c] + shift[c, None] * direction[c]
            prof = sample(smooth, q[:, None, :] + t[None, :, None] * direction[c, None, :])
            f = (prof - 0.5 * (la[c] + lb[c])[:, None]) * np.sign(lb[c] - la[c])[:, None]
            reach_level = (0.5 - EDGE_SHARE) * np.abs(lb[c] - la[c])
            found[c] = ((f[:, t <= 0].min(axis=1) <= -reach_level)
                        & (f[:, t >= 0].max(axis=1) >= reach_level))
    cand, direction, shift = cand[found], direction[found], shift[found]
    if len(cand) == 0:
        return moved, 0
    # each vertex alone: no incident element inverted or squashed, else half the shift
    vt_v, vt_t = tri.ravel(), np.repeat(np.arange(len(tri)), dim + 1)
    inc_t = vt_t[np.argsort(vt_v, kind="stable")]
    starts = np.concatenate([[0], np.cumsum(np.bincount(vt_v, minlength=n))])
    near = np.zeros(n, bool)  # the elements a move can change: the rule is checked on those
    near[cand] = True
    reach_t = np.flatnonzero(near[tri].any(axis=1))
    quality = _Quality(pts, tri, min_dihedral_deg, reach_t)
    accepted = np.zeros(len(cand), bool)
    for _ in range(BACKTRACK_STEPS + 1):
        todo = np.flatnonzero(~accepted & (shift != 0))
        if len(todo) == 0:
            break
        good = _moves_valid(pts, tri, quality, inc_t, starts, cand[todo],
                            pts[cand[todo]] + shift[todo, None] * direction[todo])
        accepted[todo[good]] = True
        shift[todo[~good]] *= 0.5
    cand, new = cand[accepted], pts[cand[accepted]] + shift[accepted, None] * direction[accepted]
    moved[cand] = new
    # together: undo the moves around any element the combination spoils
    active = np.ones(len(cand), bool)
    for _ in range(len(cand) + 1):
        bad = reach_t[quality.bad(moved, tri[reach_t], reach_t)]
        if not len(bad):
            break
        spoiled = np.isin(cand, np.unique(tri[bad])) & active
        if not spoiled.any():  # an element bad before any move: not ours to fix
            break
        moved[cand[spoiled]] = pts[cand[spoiled]]
        active &= ~spoiled
    return moved, int(active.sum())


def _moves_valid(pts, tri, quality, inc_t, starts, verts, targets):
    """For each vertex, whether moving it alone to its target keeps every incident element
    within ``quality``'s rule (a :class:`_Quality`)."""
    counts = starts[verts + 1] - starts[verts]
    owner = np.repeat(np.arange(len(verts)), counts)
    offs = np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)
    t = inc_t[starts[verts][owner] + offs]
    p = pts[tri[t]].copy()
    slot = tri[t] == verts[owner][:, None]
    p[slot] = targets[owner]
    k = tri.shape[1]
    bad_t = quality.bad(p.reshape(-1, pts.shape[1]), np.arange(k * len(p)).reshape(-1, k), t)
    return np.bincount(owner, bad_t, len(verts)) == 0


@dataclass
class MovedMesh:
    """A segmented mesh after :func:`subpixel_mesh`.

    Attributes
    ----------
    points : (n, 2) or (n, 3) float64 ndarray
    gray : (m,) float64 ndarray, measured again where a vertex moved
    material : (m,) int64 ndarray
    material_gray : (K,) ndarray or None
        Each material's area- (volume-) weighted mean gray, ascending (None without
        ``renumber``).
    n_moved : int
    """

    points: np.ndarray
    gray: np.ndarray
    material: np.ndarray
    material_gray: object
    n_moved: int


def subpixel_mesh(image, points, triangles, gray, material,
                  subpixel_max_shift=DEFAULTS.subpixel_max_shift, renumber=True, *,
                  spacing=None, smooth_px=0.0, min_dihedral_deg=0.0, edge_px=0.0):
    """A segmented mesh with its boundary vertices at the ISO-50 crossings
    (:func:`place_boundary_vertices`), each material's level from its elements away from
    the boundary (:func:`material_levels_of_mesh`), and the grays of the elements around
    a moved vertex measured again (:func:`ctseg.triangle_gray`, or the exact voxel
    overlaps of :func:`ctseg.tetra_gray.tetra_gray` for tetrahedra over a volume). With
    ``renumber`` the materials are numbered again by ascending mean gray (the moves change
    the means a little: on a coarse mesh, their order); without, the numbers stay.
    ``spacing``, ``smooth_px``, ``min_dihedral_deg`` and ``edge_px`` are passed on.

    Returns
    -------
    MovedMesh

    Example
    -------
    >>> img = np.where(np.arange(20)[None, :] < 9.7, 10.0, 90.0).repeat(20, 0)
    >>> pts = np.array([[0, 0], [19, 0], [19, 19], [0, 19], [9, 0], [9, 19], [9, 9.5]], float)
    >>> tri = np.array([[0, 4, 6], [4, 1, 6], [1, 2, 6], [2, 5, 6], [5, 3, 6], [3, 0, 6]])
    >>> mat = np.array([0, 1, 1, 1, 0, 0])
    >>> out = subpixel_mesh(img, pts, tri, triangle_gray(img, pts, tri), mat)
    >>> out.n_moved, bool(abs(out.points[6, 0] - 9.5) < 0.1)  # the edge is at x = 9.5
    (1, True)
    """
    pts = np.asarray(points, float)
    tri = np.asarray(triangles, np.int64)
    mat = np.asarray(material, np.int64)
    new_gray = np.array(gray, float)
    if len(tri) == 0:
        return MovedMesh(pts.copy(), new_gray, mat, np.zeros(0) if renumber else None, 0)
    n_mat = int(mat.max()) + 1
    # vertices between materials: their elements do not measure a material's level
    interior = ~(_vertex_materials(tri, mat, len(pts))[2] > 1)[tri].any(axis=1)
    area = element_measures(pts, tri)
    levels = material_levels_of_mesh(new_gray, area, mat, interior, n_mat)
    moved, n_moved = place_boundary_vertices(pts, tri, mat, image, levels,
                                             max_shift_fraction=subpixel_max_shift,
                                             smooth_px=smooth_px, spacing=spacing,
                                             min_dihedral_deg=min_dihedral_deg,
                                             edge_px=edge_px)
    touched = np.any(moved[tri] != pts[tri], axis=(1, 2))
    if touched.any():  # only elements with a moved vertex change
        new_gray[touched] = (triangle_gray(image, moved, tri[touched]) if pts.shape[1] == 2 else
                             VoxelOverlaps(moved, tri[touched], np.shape(image),
                                           (1.0, 1.0, 1.0) if spacing is None else spacing
                                           ).tetra_mean(np.asarray(image, float)))
    mat_gray = None
    if renumber:
        mat, mat_gray, _ = order_by_gray(mat, new_gray, element_measures(moved, tri))
    return MovedMesh(moved, new_gray, mat, mat_gray, n_moved)
