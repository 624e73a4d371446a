"""Finite-element meshes of a 3D segmentation, written by meshio (one maintained writer per
FE format), in world coordinates, with the sets of :func:`ctseg.fe_mesh.fe_sets`:

- ``.msh``: Gmsh 4.1 (binary). One physical volume per material (``material_<k>``, tag
  k + 1), one physical surface per pair of touching materials (``interface_<a>_<b>``) and
  per side of the box (``x_min`` ... ``z_max``), each on an elementary entity of its own;
  the triangles of the surfaces are faces of the tetrahedra and share their nodes.
- ``.inp``: Abaqus. C3D4 elements, an element set ``material_<k>`` with a
  ``*SOLID SECTION`` per material (its ``*MATERIAL`` is named, its properties left to the
  analyst: ctseg knows gray levels, not moduli) and a node set per side of the box.
- ``.xdmf``: XDMF with the data inline (XML: one file, no HDF5), the tetrahedra with cell
  data ``material`` and ``gray``.
"""
import os

import numpy as np

from ctseg.errors import MeshCheckError
from ctseg.fe_mesh import BOX_SIDES, fe_sets

from .convert3d import world_map, world_tetrahedra
from .writers import atomic_outputs

FE_FORMATS = {".msh": "Gmsh 4.1", ".inp": "Abaqus", ".xdmf": "XDMF"}
"""Finite-element formats, by extension."""


def segmentation_fe_sets(result, geometry=None):
    """:func:`ctseg.fe_mesh.fe_sets` of a TetraSegmentation, its facets oriented in world
    space (reversed where the direction matrix flips)."""
    box = (np.asarray(result.shape[::-1], float) - 1.0) * np.asarray(result.spacing, float)
    sets = fe_sets(result.points, result.tetrahedra, result.material, result.interfaces,
                   result.interface_materials, box)
    if world_map(result, geometry)[1]:
        for facets in (sets.interface_facets, sets.side_facets):
            for name in facets:
                facets[name] = facets[name][:, ::-1]
    return sets


def _node_entities(n_points, blocks):
    """One (dim, tag) per node, as Gmsh files classify nodes: the entity of the lowest
    dimension holding it (meshio builds the $Entities section from the nodes), then every
    entity that got no node takes one of its own that another entity can spare."""
    dim_tags = np.zeros((n_points, 2), np.int64)
    for dim, tag, cells in sorted(blocks, key=lambda b: -b[0]):
        dim_tags[np.unique(cells)] = (dim, tag)
    for dim, tag, cells in sorted(blocks, key=lambda b: len(np.unique(b[2]))):
        if np.any((dim_tags[:, 0] == dim) & (dim_tags[:, 1] == tag)):
            continue
        code = dim_tags[:, 0] * (1 << 32) + dim_tags[:, 1]
        _, inverse, counts = np.unique(code, return_inverse=True, return_counts=True)
        nodes = np.unique(cells)
        spare = nodes[counts[inverse[nodes]] > 1]
        if not len(spare):
            raise MeshCheckError(f"Gmsh export: entity ({dim}, {tag}) shares all its nodes "
                                 "with entities that need them; nothing was written")
        dim_tags[spare[0]] = (dim, tag)
    return dim_tags


def gmsh_mesh(result, geometry=None):
    """The meshio.Mesh of the .msh export (see the module's docstring)."""
    import meshio

    points, tets = world_tetrahedra(result, geometry)
    sets = segmentation_fe_sets(result, geometry)
    blocks, names = [], {}
    for name, elements in sets.element_sets.items():
        tag = int(name.rsplit("_", 1)[1]) + 1
        blocks.append((3, tag, tets[elements]))
        names[name] = (tag, 3)
    surfaces = [(s, sets.side_facets[s]) for s in BOX_SIDES if s in sets.side_facets]
    surfaces += list(sets.interface_facets.items())
    for tag, (name, facets) in enumerate(surfaces, start=1):
        blocks.append((2, tag, facets))
        names[name] = (tag, 2)
    return meshio.Mesh(
        points, [("tetra" if dim == 3 else "triangle", cells) for dim, _, cells in blocks],
        point_data={"gmsh:dim_tags": _node_entities(len(points), blocks)},
        cell_data={key: [np.full(len(cells), tag, np.int64) for _, tag, cells in blocks]
                   for key in ("gmsh:physical", "gmsh:geometrical")},
        field_data={name: np.array(tag_dim) for name, tag_dim in names.items()})


def abaqus_mesh(result, geometry=None):
    """The meshio.Mesh of the .inp export, and the lines that follow meshio's: a section
    and a (named) material per element set."""
    import meshio

    points, tets = world_tetrahedra(result, geometry)
    sets = segmentation_fe_sets(result, geometry)
    mesh = meshio.Mesh(points, [("tetra", tets)],
                       cell_sets={name: [idx] for name, idx in sets.element_sets.items()},
                       point_sets=dict(sets.side_nodes))
    lines = []
    for name in sets.element_sets:
        k = int(name.rsplit("_", 1)[1])
        lines += [f"** {name}: gray level {result.material_gray[k]:.6g} (input units)",
                  f"*SOLID SECTION, ELSET={name}, MATERIAL={name}", ",",
                  f"*MATERIAL, NAME={name}"]
    return mesh, lines


def xdmf_mesh(result, geometry=None):
    """The meshio.Mesh of the .xdmf export: tetrahedra with ``material`` and ``gray``."""
    import meshio

    points, tets = world_tetrahedra(result, geometry)
    return meshio.Mesh(points, [("tetra", tets)],
                       cell_data={"material": [np.asarray(result.material, np.int32)],
                                  "gray": [np.asarray(result.gray, np.float64)]})


def write_fe_mesh(result, path, geometry=None):
    """Write a TetraSegmentation as a finite-element mesh (:data:`FE_FORMATS`), whole or
    not at all. The caller checks the path and the segmentation first
    (:func:`ctseg.filters.writers3d.write_tetra_mesh` does). Returns ``[path]``."""
    import meshio

    path = os.fspath(path)
    ext = os.path.splitext(path)[1].lower()
    with atomic_outputs([path]) as (tmp,):
        if ext == ".msh":
            meshio.write(tmp, gmsh_mesh(result, geometry), file_format="gmsh", binary=True)
        elif ext == ".inp":
            mesh, lines = abaqus_mesh(result, geometry)
            meshio.write(tmp, mesh, file_format="abaqus")
            with open(tmp, "a") as fh:
                fh.write("\n".join(lines) + "\n")
        else:
            meshio.write(tmp, xdmf_mesh(result, geometry), file_format="xdmf", data_format="XML")
    return [path]
