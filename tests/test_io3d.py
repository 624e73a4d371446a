"""The VTK layer of the 3D mode: world geometry, the checked writers and their files read
back, the rasteriser, the composite filter in a real pipeline, and the figure."""
import os

import numpy as np
import pytest

from ctseg.errors import CTSegError, MeshCheckError
from ctseg.filters import ImageGeometry, array_to_image
from ctseg.filters.convert3d import (grid_to_arrays, material_surfaces_to_polydata,
                                     tetra_segmentation_to_vtk, world_interfaces,
                                     world_surfaces, world_tetrahedra)
from ctseg.metrics import evaluate_tetra
from ctseg.raster import tetra_label_volume
from ctseg.filters.writers3d import (check_tetra_segmentation, read_unstructured_grid,
                                     write_interfaces, write_tetra_mesh)
from ctseg.meshcheck import closed_surface_report, enclosed_volume
from ctseg.pipeline3d import TetraSegmentation
from ctseg.surfaces import material_interfaces, material_surface, repair_pinched_edges
from ctseg.tetrahedra import delaunay_tetrahedra, tetra_quality, tetra_volumes

from conftest import requires_rendering

SPHERES = ((0.35, 0.5, 0.5, 0.28), (0.7, 0.45, 0.55, 0.2), (0.36, 0.5, 0.5, 0.12))


def synthetic_segmentation(shape=(6, 8, 10), spacing=(1.0, 1.0, 1.0), n_inner=80, n_face=30,
                           seed=0, spheres=SPHERES):
    """A TetraSegmentation made without the pipeline: Delaunay tetrahedra of the box's 8
    corners, random inner points and random points on its faces; material by barycentre
    in spheres (a later sphere overwrites: the third sits inside the first), pinched
    edges repaired, interfaces and closed surfaces as the pipeline makes them."""
    rng = np.random.default_rng(seed)
    sp = np.asarray(spacing, float)
    box = (np.array(shape[::-1], float) - 1.0) * sp
    corners = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], float)
    face = rng.uniform(0.05, 0.95, (n_face, 3))
    face[np.arange(n_face), rng.integers(0, 3, n_face)] = rng.integers(0, 2, n_face)
    sites = np.vstack([corners, rng.uniform(0.05, 0.95, (n_inner, 3)), face]) * box
    mesh = delaunay_tetrahedra(sites, box)
    cent = mesh.points[mesh.tetrahedra].mean(axis=1) / box
    mat = np.zeros(len(cent), np.int64)
    for k, (x, y, z, r) in enumerate(spheres):
        mat[np.sum((cent - [x, y, z]) ** 2, axis=1) < r * r] = k + 1
    mat, _ = repair_pinched_edges(mesh, mat, tetra_volumes(mesh.points, mesh.tetrahedra))
    used, mat = np.unique(mat, return_inverse=True)
    faces, a, b = material_interfaces(mesh, mat)
    surfaces = [material_surface(mesh, mat, k) for k in range(len(used))]
    return TetraSegmentation(
        points=mesh.points, tetrahedra=mesh.tetrahedra, material=mat,
        gray=100.0 * mat + rng.normal(0, 1, len(mat)), adjacency=mesh.adjacency,
        interfaces=faces, interface_materials=np.column_stack([a, b]), surfaces=surfaces,
        material_gray=100.0 * np.arange(len(used)), spacing=sp, shape=tuple(shape),
        diagnostics={"mode": "3d", "element_quality": tetra_quality(mesh.points, mesh.tetrahedra)})


def _rotation(axis, angle):
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k


ROT = _rotation((1, 2, 3), 0.7)
GEOMETRIES = {
    "identity": ImageGeometry(spacing=(0.1, 0.1, 0.3)),
    "rotated": ImageGeometry(origin=(-120.0, 35.5, 980.0), spacing=(0.1, 0.1, 0.3), direction=ROT),
    "lps_det_minus_1": ImageGeometry(origin=(5.0, -7.0, 2.0), spacing=(0.1, 0.1, 0.3),
                                     direction=ROT @ np.diag([-1.0, 1.0, 1.0])),
}


@pytest.fixture(scope="module")
def seg():
    return synthetic_segmentation(spacing=(0.1, 0.1, 0.3))


def test_synthetic_segmentation_has_what_the_tests_need(seg):
    assert seg.n_materials == 4 and len(seg.surfaces) == 4
    # a material whose surface has a vertex copied per piece (pieces touching at a vertex)
    assert any(len(s.points) > len(np.unique(s.source_vertex)) for s in seg.surfaces)


@pytest.mark.parametrize("name", sorted(GEOMETRIES))
def test_world_geometry_keeps_volumes_positive_and_surfaces_outward(seg, name):
    geom = GEOMETRIES[name]
    assert (np.linalg.det(geom.direction) < 0) == (name == "lps_det_minus_1")
    pts, tets = world_tetrahedra(seg, geom)
    vol = tetra_volumes(pts, tets)
    box_volume = np.prod((np.array(seg.shape[::-1]) - 1) * np.array(geom.spacing))
    assert vol.min() > 0
    np.testing.assert_allclose(vol.sum(), box_volume, rtol=1e-9)
    # the world points are the voxel-index map of the geometry
    np.testing.assert_allclose(geom.to_index(pts), seg.points / seg.spacing, atol=1e-9)
    for k, spts, tris in world_surfaces(seg, geom):
        inside = vol[seg.material == k].sum()
        assert abs(enclosed_volume(spts, tris) - inside) <= 1e-9 * inside
    # every interface normal points into material b's tetrahedron
    ipts, faces, sides = world_interfaces(seg, geom)
    owners = {}
    for t, tet in enumerate(seg.tetrahedra):
        for f in range(4):
            owners.setdefault(tuple(sorted(np.delete(tet, f))), []).append(t)
    p = ipts[faces]
    normal = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    for face, n, (a, b), c in zip(faces, normal, sides, p.mean(axis=1)):
        pair = owners[tuple(sorted(face))]
        tb = [t for t in pair if seg.material[t] == b]
        assert a < b and len(pair) == 2 and len(tb) == 1
        assert np.dot(n, pts[tets[tb[0]]].mean(axis=0) - c) > 0


def test_vtk_objects_carry_the_arrays(seg):
    geom = GEOMETRIES["rotated"]
    grid, inter = tetra_segmentation_to_vtk(seg, geom)
    pts, tets, arrays = grid_to_arrays(grid)
    assert len(tets) == len(seg.tetrahedra) and arrays["material"].dtype == np.int32
    assert np.array_equal(arrays["material"], seg.material) and arrays["gray"].dtype == np.float64
    assert inter.GetNumberOfCells() == len(seg.interfaces)
    assert inter.GetCellData().GetArray("material_b").GetNumberOfTuples() == len(seg.interfaces)
    poly = material_surfaces_to_polydata(seg, geom)
    assert poly.GetNumberOfCells() == sum(len(s.triangles) for s in seg.surfaces)


def test_check_reports_every_surface(seg):
    report = check_tetra_segmentation(seg, GEOMETRIES["lps_det_minus_1"])
    assert report["ok"] and [r["material"] for r in report["surfaces"]] == [0, 1, 2, 3]
    for r in report["surfaces"]:
        assert r["boundary_edges"] == 0 and r["self_intersecting_faces"] == 0
        assert r["volume_rel_error"] < 1e-9 and r["enclosed_volume"] > 0


# ------------------------------------------------------------- each written file read back
def _read_vtp(path):
    from ctseg.filters import polydata_to_arrays, read_polydata

    return polydata_to_arrays(read_polydata(path))


def _load(path):
    """(vertices, faces, face colours or None, face quality or None) as pymeshlab reads
    a file (an STL's coincident vertices unified)."""
    import pymeshlab

    ms = pymeshlab.MeshSet()
    ms.load_new_mesh(str(path))
    m = ms.current_mesh()
    m.compact()
    colours = m.face_color_matrix() if m.has_face_color() else None
    quality = m.face_scalar_array() if m.has_face_scalar() else None
    return m.vertex_matrix(), m.face_matrix(), colours, quality


@pytest.mark.parametrize("ext", [".vtu", ".vtp", ".stl", ".ply", ".obj"])
def test_each_format_reopens_with_counts_materials_and_volumes(seg, tmp_path, ext):
    geom = GEOMETRIES["lps_det_minus_1"]
    written, checks = write_tetra_mesh(seg, tmp_path / f"m{ext}", geom)
    assert checks["ok"] and all(os.path.exists(w) for w in written)
    mask = os.umask(0o022)
    os.umask(mask)
    assert all(os.stat(w).st_mode & 0o777 == 0o666 & ~mask for w in written)  # not mkstemp's 0600
    assert not [f for f in os.listdir(tmp_path) if f.startswith(".ctseg-")]
    _, tets = world_tetrahedra(seg, geom)
    vol = tetra_volumes(world_tetrahedra(seg, geom)[0], tets)
    per_material = [vol[seg.material == k].sum() for k in range(seg.n_materials)]
    n_tri = [len(s.triangles) for s in seg.surfaces]
    if ext == ".vtu":
        pts, tets, arrays = grid_to_arrays(read_unstructured_grid(written[0]))
        assert np.array_equal(arrays["material"], seg.material)
        np.testing.assert_allclose(arrays["gray"], seg.gray)
        v = tetra_volumes(pts, tets)
        assert v.min() > 0
        np.testing.assert_allclose([v[arrays["material"] == k].sum() for k in range(4)],
                                   per_material, rtol=1e-12)
        return
    if ext == ".vtp":
        pts, tri, arrays = _read_vtp(written[0])
        mats = arrays["material"]
        meshes = [(pts, tri[mats == k]) for k in range(4)]
    elif ext == ".stl":
        assert [os.path.basename(w) for w in written] == [f"m_material{k}.stl" for k in range(4)]
        meshes = [_load(w)[:2] for w in written]
    else:
        verts, faces, colours, quality = _load(written[0])
        rgb = np.round(colours[:, :3] * 255).astype(int)
        from ctseg.filters.writers import material_colors

        mats = np.full(len(rgb), -1)
        for k, c in enumerate(material_colors(np.arange(4)).astype(int)):
            mats[np.all(np.abs(rgb - c) <= 1, axis=1)] = k
        assert mats.min() == 0
        if ext == ".ply":
            assert np.array_equal(quality.astype(int), mats)
        else:
            assert os.path.basename(written[1]) == "m.mtl"
        meshes = [(verts, faces[mats == k]) for k in range(4)]
    assert [len(t) for _, t in meshes] == n_tri
    # float32 formats (STL, PLY) and 9-digit OBJ keep the volumes to about 1e-6
    rtol = 1e-12 if ext == ".vtp" else 2e-5
    for (p, t), expected in zip(meshes, per_material):
        np.testing.assert_allclose(enclosed_volume(p, t), expected, rtol=rtol)


def test_interfaces_file(seg, tmp_path):
    path = write_interfaces(seg, tmp_path / "s.vtp", GEOMETRIES["rotated"])
    pts, tri, arrays = _read_vtp(path)
    assert len(tri) == len(seg.interfaces)
    assert np.all(arrays["material_a"] < arrays["material_b"])
    assert np.array_equal(arrays["material_a"], seg.interface_materials[:, 0])


# --------------------------------------------------------- a failed check writes nothing
def _broken(seg, how):
    import copy

    bad = copy.deepcopy(seg)
    s = bad.surfaces[1]
    if how == "hole":
        s.triangles = s.triangles[1:]
    elif how == "flipped":
        s.triangles = s.triangles.copy()
        s.triangles[0] = s.triangles[0, ::-1]
    elif how == "inverted_tetrahedron":
        bad.tetrahedra = bad.tetrahedra.copy()
        bad.tetrahedra[0] = bad.tetrahedra[0, [0, 2, 1, 3]]
    elif how == "missing_surface":
        bad.surfaces = bad.surfaces[:-1]
    return bad


@pytest.mark.parametrize("how,words", [
    ("hole", ["material 1 surface", "boundary_edges"]),
    ("flipped", ["material 1 surface", "inconsistently_oriented_edges"]),
    ("inverted_tetrahedron", ["volume <= 0"]),
    ("missing_surface", ["no closed surface"]),
])
@pytest.mark.parametrize("ext", [".vtu", ".stl", ".obj"])
def test_a_failed_check_writes_nothing(seg, tmp_path, how, words, ext):
    with pytest.raises(MeshCheckError) as info:
        write_tetra_mesh(_broken(seg, how), tmp_path / f"m{ext}", GEOMETRIES["rotated"])
    for word in words:
        assert word in str(info.value)
    assert "nothing was written" in str(info.value) and os.listdir(tmp_path) == []


def test_closed_surface_report_finds_self_intersection_and_volume_mismatch():
    tet = np.array([[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]])
    a = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float)
    ok = closed_surface_report(a, tet, 1 / 6)
    assert ok["ok"] and ok["self_intersecting_faces"] == 0
    # two closed tetrahedra, one through the other: each closed, together crossing
    two = closed_surface_report(np.vstack([a, a + 0.3]), np.vstack([tet, tet + 4]), 2 / 6)
    assert not two["ok"] and two["self_intersecting_faces"] > 0 and two["boundary_edges"] == 0
    wrong = closed_surface_report(a, tet, 1 / 6 * (1 + 1e-6))
    assert not wrong["ok"] and wrong["volume_mismatch"] == 1
    inward = closed_surface_report(a, tet[:, ::-1])
    assert not inward["ok"] and inward["inward"] == 1


# ------------------------------------------------------------------------- rasteriser
def test_rasteriser_puts_each_voxel_in_a_tetrahedron_holding_it(seg):
    import ctseg.raster as raster

    labels = tetra_label_volume(seg.points, seg.tetrahedra, seg.material, seg.shape, seg.spacing)
    kk, jj, ii = np.indices(seg.shape)
    centres = np.column_stack([ii.ravel(), jj.ravel(), kk.ravel()]) * seg.spacing
    p = seg.points[seg.tetrahedra]
    T = np.linalg.inv(np.transpose(p[:, 1:] - p[:, :1], (0, 2, 1)))
    lam = np.einsum("tij,vtj->vti", T, centres[:, None, :] - p[None, :, 0])
    inside = np.all(lam >= -1e-9, axis=2) & (lam.sum(axis=2) <= 1 + 1e-9)  # (voxels, tets)
    holders = [set(seg.material[np.flatnonzero(row)].tolist()) for row in inside]
    assert all(h for h in holders)
    assert all(lab in h for lab, h in zip(labels.ravel(), holders))
    old = raster.CANDIDATES_PER_CHUNK
    try:
        raster.CANDIDATES_PER_CHUNK = 37  # many chunks: the same labels
        assert np.array_equal(tetra_label_volume(seg.points, seg.tetrahedra, seg.material,
                                                 seg.shape, seg.spacing), labels)
    finally:
        raster.CANDIDATES_PER_CHUNK = old
    acc = evaluate_tetra(seg, labels)
    assert acc["dice"] == [1.0] * (int(labels.max()) + 1) and acc["min_dice"] == 1.0
    with pytest.raises(CTSegError, match="truth: shape"):
        evaluate_tetra(seg, labels[1:])


# ------------------------------------------------------------ the filter in a pipeline
def test_segment_filter_3d_in_a_real_pipeline(tmp_path):
    from vtkmodules.vtkIOXML import (vtkXMLImageDataReader, vtkXMLImageDataWriter,
                                     vtkXMLUnstructuredGridWriter)

    from ctseg.filters import CTSegmentFilter
    from ctseg.phantoms import make_volume

    vol = make_volume(8, 20, seed=3).image
    geom = ImageGeometry(origin=(10.0, -5.0, 2.0), spacing=(0.1, 0.1, 0.3))
    w = vtkXMLImageDataWriter()
    w.SetFileName(str(tmp_path / "v.vti"))
    w.SetInputData(array_to_image(vol, geom))
    assert w.Write() == 1
    reader = vtkXMLImageDataReader()
    reader.SetFileName(str(tmp_path / "v.vti"))
    f = CTSegmentFilter()
    f.SetMode("3d")
    f.SetNumberOfSites(200)
    f.SetInputConnection(reader.GetOutputPort())
    progress = []
    f.AddObserver("ProgressEvent", lambda obj, _: progress.append(obj.GetProgress()))
    writer = vtkXMLUnstructuredGridWriter()
    writer.SetFileName(str(tmp_path / "t.vtu"))
    writer.SetInputConnection(f.GetOutputPort(0))
    assert writer.Write() == 1 and f.last_error is None
    assert f.GetOutputDataObject(1).GetClassName() == "vtkPolyData"
    assert f.GetOutputDataObject(1).GetNumberOfCells() == len(f.result.interfaces)
    pts, tets, arrays = grid_to_arrays(read_unstructured_grid(tmp_path / "t.vtu"))
    assert len(tets) == len(f.result.tetrahedra) and set(arrays) >= {"material", "gray"}
    assert set(np.unique(arrays["material"])) == set(range(f.result.n_materials))
    vol_t = tetra_volumes(pts, tets)
    assert vol_t.min() > 0
    np.testing.assert_allclose(vol_t.sum(), 1.9 * 1.9 * 2.1, rtol=1e-9)
    np.testing.assert_allclose(pts.min(axis=0), geom.origin, atol=1e-9)
    np.testing.assert_allclose(pts.max(axis=0), np.add(geom.origin, [1.9, 1.9, 2.1]), atol=1e-9)
    assert progress and progress[-1] == 1.0 and len(set(progress)) > 3
    f.SetMode("slices")  # the output type follows the mode
    f.Update()
    assert f.GetOutputDataObject(0).GetClassName() == "vtkPolyData" and f.last_error is None
    f.SetMode("3d")
    with pytest.raises(CTSegError, match="one slice; Mode '3d' needs a volume"):
        f.apply(array_to_image(vol[0], geom))


# ------------------------------------------------------------------------- the figure
@requires_rendering
def test_volume_figure(seg, tmp_path):
    from ctseg.filters.figure3d import render_volume_figure
    from ctseg.filters.writers import PALETTE

    vol = np.zeros(seg.shape)
    rgb = render_volume_figure(tmp_path / "f.png", vol, seg, title="synthetic")
    assert os.path.getsize(tmp_path / "f.png") > 0 and rgb.shape[2] == 3
    h, w = rgb.shape[0] // 2, rgb.shape[1] // 2
    for panel in (rgb[:h, :w], rgb[:h, w:], rgb[h:, :w], rgb[h:, w:]):
        assert (panel.sum(axis=2) < 600).mean() > 0.05  # drawn, not blank
    # the outlines (red) in the slices, and the surfaces in their material colours
    red = (rgb[..., 0] > 200) & (rgb[..., 1] < 60) & (rgb[..., 2] < 60)
    assert red[:h].sum() > 50
    surf = rgb[h:, w:].reshape(-1, 3).astype(int)
    for k in (1, 2):
        c = PALETTE[k].astype(int)
        # lit surfaces: some pixels of the material's hue (colour up to a brightness factor)
        unit = surf / np.maximum(np.linalg.norm(surf, axis=1, keepdims=True), 1)
        assert np.sum(unit @ (c / np.linalg.norm(c)) > 0.995) > 20, k
    with pytest.raises(CTSegError, match="unknown output format"):
        render_volume_figure(tmp_path / "f.jpg", vol, seg)


def test_the_slices_conversion_refuses_a_3d_result(seg):
    from ctseg.filters import segmentation_to_polydata

    with pytest.raises(CTSegError, match="tetra_segmentation_to_vtk"):
        segmentation_to_polydata(seg)
