"""The finite-element view of a segmented tetrahedral mesh: one element set per material,
one facet set per pair of touching materials, one facet set and one node set per side of
the box, as FE pre-processors want them for sections, contact and boundary conditions.

The tetrahedra are the mesh's own (conforming: neighbours share whole faces), so every
facet set is made of faces of the tetrahedra and uses their nodes.
"""
from dataclasses import dataclass

import numpy as np

from .tetrahedra import face_graph

BOX_SIDES = ("x_min", "x_max", "y_min", "y_max", "z_min", "z_max")
"""The box's sides, by image axis (x along columns i, y along rows j, z along slices k)."""


@dataclass(frozen=True)
class FESets:
    """Named sets of a tetrahedral mesh.

    Attributes
    ----------
    element_sets : dict of str -> (e,) int64 ndarray
        ``material_<k>``: the tetrahedra of material k, for every material present.
    interface_facets : dict of str -> (f, 3) int64 ndarray
        ``interface_<a>_<b>`` (a < b): the faces between materials a and b, normals from
        a into b.
    side_facets : dict of str -> (f, 3) int64 ndarray
        For each side of :data:`BOX_SIDES` the mesh touches: its boundary faces, outward.
    side_nodes : dict of str -> (n,) int64 ndarray
        The nodes on each side (a node on an edge of the box is on two sides).
    """

    element_sets: dict
    interface_facets: dict
    side_facets: dict
    side_nodes: dict


def fe_sets(points, tetrahedra, material, interfaces, interface_materials, box):
    """Element sets per material, facet sets per interface and per box side.

    Parameters
    ----------
    points : (n, 3) float ndarray
        In the box's frame: the box is ``[0, box[0]] x [0, box[1]] x [0, box[2]]``.
    tetrahedra : (m, 4) int ndarray
        Positively oriented, conforming, covering the box.
    material : (m,) int ndarray
    interfaces : (f, 3) int ndarray
        Faces between materials, oriented from ``interface_materials[:, 0]``.
    interface_materials : (f, 2) int ndarray
        The two materials of each face, the lower first.
    box : (3,) floats
        The box's extent along x, y, z.

    Returns
    -------
    FESets

    Raises
    ------
    ValueError
        A boundary face that lies on no side of the box (the tetrahedra do not cover it).

    Examples
    --------
    >>> import numpy as np
    >>> from ctseg.tetrahedra import delaunay_tetrahedra
    >>> cube = delaunay_tetrahedra(np.array([[x, y, z] for x in (0, 1) for y in (0, 1)
    ...                                      for z in (0, 1)], float), (1, 1, 1))
    >>> s = fe_sets(cube.points, cube.tetrahedra, np.zeros(len(cube.tetrahedra), int),
    ...             np.zeros((0, 3), int), np.zeros((0, 2), int), (1, 1, 1))
    >>> [len(s.side_facets[side]) for side in BOX_SIDES], len(s.side_nodes["x_min"])
    ([2, 2, 2, 2, 2, 2], 4)
    """
    points = np.asarray(points, float)
    material = np.asarray(material, np.int64)
    box = np.asarray(box, float)
    element_sets = {f"material_{k}": np.flatnonzero(material == k) for k in np.unique(material)}
    pairs = np.asarray(interface_materials, np.int64).reshape(-1, 2)
    faces = np.asarray(interfaces, np.int64).reshape(-1, 3)
    interface_facets = {}
    for a, b in np.unique(pairs, axis=0):
        interface_facets[f"interface_{a}_{b}"] = faces[(pairs[:, 0] == a) & (pairs[:, 1] == b)]
    _, _, boundary, _ = face_graph(tetrahedra)
    # each side's nodes are set exactly on its plane (corner, edge and face sites keep
    # their coordinates), so a tolerance only guards rounding in the spacing
    tol = 1e-9 * max(float(box.max()), 1.0)
    side_facets, side_nodes = {}, {}
    placed = np.zeros(len(boundary), bool)
    for s, name in enumerate(BOX_SIDES):
        axis, plane = s // 2, (0.0 if s % 2 == 0 else box[s // 2])
        on_plane = np.abs(points[:, axis] - plane) <= tol
        here = on_plane[boundary].all(axis=1)
        placed |= here
        if here.any():
            side_facets[name] = boundary[here]
            side_nodes[name] = np.flatnonzero(on_plane)
    if not placed.all():
        raise ValueError(f"{int((~placed).sum())} boundary face(s) lie on no side of the box: "
                         "the tetrahedra do not cover it")
    return FESets(element_sets, interface_facets, side_facets, side_nodes)
