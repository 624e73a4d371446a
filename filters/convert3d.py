"""numpy <-> VTK for the 3D mode: a :class:`ctseg.pipeline3d.TetraSegmentation`'s
tetrahedra, interface triangles and closed per-material surfaces in world coordinates.

Its points are (i, j, k) index x spacing; world points are
``ImageGeometry.to_world(index)`` (origin, spacing, direction). A direction matrix with a
negative determinant (an LPS flip) would turn every element inside out: two vertices of
every tetrahedron are then swapped and every triangle reversed, so that volumes stay
positive and normals point outward (and from ``material_a`` to ``material_b``) in world
space."""
import numpy as np
from vtkmodules.util import numpy_support
from vtkmodules.vtkCommonDataModel import vtkPolyData

from ctseg.errors import InputError
from ctseg.geometry import ImageGeometry

from .convert import _add_cell_array, _cells, _points, cell_arrays


def world_map(result, geometry=None):
    """(to_world, flips) for a :class:`ctseg.pipeline3d.TetraSegmentation`: its points are
    (i, j, k) index x ``result.spacing``; ``to_world`` maps such points through
    ``geometry`` (default: the result's spacing alone), and ``flips`` says that the
    direction matrix has a negative determinant (an LPS flip), which turns every
    tetrahedron and triangle inside out unless two of its vertices are swapped."""
    spacing = np.asarray(result.spacing, float)
    geometry = geometry or ImageGeometry(spacing=spacing)
    flips = bool(np.linalg.det(geometry.direction) < 0)
    return (lambda pts: geometry.to_world(np.asarray(pts, float).reshape(-1, 3) / spacing)), flips


def tetrahedra_to_world(points, tetrahedra, spacing, geometry=None):
    """World points and tetrahedra of box-coordinate tetrahedra (points = index x
    ``spacing``), each positively oriented in world space (two vertices swapped where the
    direction flips)."""
    spacing = np.asarray(spacing, float)
    geometry = geometry or ImageGeometry(spacing=spacing)
    tets = np.asarray(tetrahedra, np.int64)
    world = geometry.to_world(np.asarray(points, float).reshape(-1, 3) / spacing)
    return world, (tets[:, [0, 2, 1, 3]] if np.linalg.det(geometry.direction) < 0 else tets)


def world_tetrahedra(result, geometry=None):
    """World points and tetrahedra of a TetraSegmentation (:func:`tetrahedra_to_world`)."""
    return tetrahedra_to_world(result.points, result.tetrahedra, result.spacing, geometry)


def world_surfaces(result, geometry=None):
    """Every material's closed surface as (material, world points, triangles), outward
    in world space (triangles reversed where the direction flips)."""
    to_world, flips = world_map(result, geometry)
    return [(int(s.material), to_world(s.points),
             np.asarray(s.triangles, np.int64)[:, ::-1] if flips else np.asarray(s.triangles, np.int64))
            for s in result.surfaces]


def world_interfaces(result, geometry=None):
    """World points and interface triangles (normal from ``material_a`` to ``material_b``
    in world space), and the (f, 2) materials."""
    to_world, flips = world_map(result, geometry)
    faces = np.asarray(result.interfaces, np.int64).reshape(-1, 3)
    return (to_world(result.points), faces[:, ::-1] if flips else faces,
            np.asarray(result.interface_materials, np.int64).reshape(-1, 2))


def tetra_grid(points, tetrahedra, material, gray):
    """vtkUnstructuredGrid of VTK_TETRA cells with cell arrays ``material`` (int32) and
    ``gray`` (float64)."""
    from vtkmodules.vtkCommonDataModel import VTK_TETRA, vtkUnstructuredGrid

    grid = vtkUnstructuredGrid()
    grid.SetPoints(_points(points))
    grid.SetCells(VTK_TETRA, _cells(np.asarray(tetrahedra).ravel(), 4))
    _add_cell_array(grid, np.asarray(material, np.int32), "material")
    _add_cell_array(grid, np.asarray(gray, np.float64), "gray")
    grid.GetCellData().SetActiveScalars("material")
    return grid


def triangles_polydata(points, triangles, arrays):
    """vtkPolyData of triangles with the given {name: per-triangle values} cell arrays."""
    poly = vtkPolyData()
    poly.SetPoints(_points(np.asarray(points, float).reshape(-1, 3)))
    poly.SetPolys(_cells(np.asarray(triangles).ravel(), 3))
    for name, values in arrays.items():
        _add_cell_array(poly, np.ascontiguousarray(values), name)
    return poly


def tetra_segmentation_to_vtk(result, geometry=None):
    """A :class:`ctseg.pipeline3d.TetraSegmentation` -> (vtkUnstructuredGrid of its
    tetrahedra with ``material`` and ``gray``, vtkPolyData of its interface triangles
    with ``material_a`` and ``material_b``), in world coordinates (``geometry``: the
    image's origin, spacing and direction; default the result's spacing alone), volumes
    positive and interface normals from a to b in world space."""
    pts, tets = world_tetrahedra(result, geometry)
    grid = tetra_grid(pts, tets, result.material, result.gray)
    ipts, faces, sides = world_interfaces(result, geometry)
    inter = triangles_polydata(ipts, faces, {"material_a": sides[:, 0].astype(np.int32),
                                             "material_b": sides[:, 1].astype(np.int32)})
    return grid, inter


def surfaces_to_arrays(result, geometry=None):
    """All closed surfaces in one mesh: (world points, triangles, material per triangle);
    each material keeps its own vertices."""
    parts = world_surfaces(result, geometry)
    offsets = np.cumsum([0] + [len(p) for _, p, _ in parts])
    points = np.concatenate([p for _, p, _ in parts]) if parts else np.zeros((0, 3))
    tris = (np.concatenate([t + o for (_, _, t), o in zip(parts, offsets)]) if parts
            else np.zeros((0, 3), np.int64))
    mats = (np.concatenate([np.full(len(t), k, np.int64) for k, _, t in parts]) if parts
            else np.zeros(0, np.int64))
    return points, tris, mats


def material_surfaces_to_polydata(result, geometry=None):
    """Every material's closed surface in one vtkPolyData (world coordinates, outward),
    with a ``material`` cell array."""
    points, tris, mats = surfaces_to_arrays(result, geometry)
    poly = triangles_polydata(points, tris, {"material": mats.astype(np.int32)})
    poly.GetCellData().SetActiveScalars("material")
    return poly


def grid_to_arrays(grid):
    """vtkUnstructuredGrid of tetrahedra -> (points (n, 3), tetrahedra (m, 4),
    {cell array name: values})."""
    from vtkmodules.vtkCommonDataModel import VTK_TETRA

    pts = numpy_support.vtk_to_numpy(grid.GetPoints().GetData()) if grid.GetPoints() else np.zeros((0, 3))
    n = grid.GetNumberOfCells()
    if n:
        types = numpy_support.vtk_to_numpy(grid.GetDistinctCellTypesArray())
        if not np.all(types == VTK_TETRA):
            raise InputError("unstructured grid: only tetrahedra are supported")
        conn = numpy_support.vtk_to_numpy(grid.GetCells().GetConnectivityArray())
        tets = conn.reshape(-1, 4).astype(np.int64)
    else:
        tets = np.zeros((0, 4), np.int64)
    return np.array(pts), tets, cell_arrays(grid)
