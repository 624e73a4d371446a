"""Finite-element exports of the 3D mode, read back by the programs they are for: the .msh
by Gmsh's own Python API, the .inp and .xdmf by meshio, and the .msh solved for steady
heat conduction by scikit-fem (one conductivity per material)."""
import os

import numpy as np
import pytest

from ctseg.errors import InputError
from ctseg.fe_mesh import BOX_SIDES, fe_sets
from ctseg.filters import ImageGeometry
from ctseg.filters.convert3d import world_tetrahedra
from ctseg.filters.writers3d import write_tetra_mesh
from ctseg.tetrahedra import face_graph, tetra_volumes

from test_io3d import _rotation, synthetic_segmentation

gmsh = pytest.importorskip("gmsh")
skfem = pytest.importorskip("skfem")

SPACING = (0.5, 0.4, 0.7)
GEOM = ImageGeometry(origin=(1.0, 2.0, 3.0), spacing=SPACING)


@pytest.fixture(scope="module")
def seg():
    return synthetic_segmentation(shape=(8, 10, 12), spacing=SPACING, n_inner=300, n_face=120)


def _gmsh_groups(path):
    """{physical name: (dim, element count)} and the tetrahedra's minimum signed inverse
    condition number (negative for an inverted element), as Gmsh reads the file."""
    gmsh.initialize(["-noenv"])
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.open(path)
        groups = {}
        for dim, tag in gmsh.model.getPhysicalGroups():
            n = 0
            for ent in gmsh.model.getEntitiesForPhysicalGroup(dim, tag):
                _, elements, _ = gmsh.model.mesh.getElements(dim, ent)
                n += sum(len(e) for e in elements)
            groups[gmsh.model.getPhysicalName(dim, tag)] = (dim, n)
        tet_type = gmsh.model.mesh.getElementType("Tetrahedron", 1)
        tags, _ = gmsh.model.mesh.getElementsByType(tet_type)
        sicn = np.asarray(gmsh.model.mesh.getElementQualities(tags, "minSICN"))
        node_tags, coords, _ = gmsh.model.mesh.getNodes()
        coords = np.asarray(coords).reshape(-1, 3)[np.argsort(node_tags)]
    finally:
        gmsh.finalize()
    return groups, sicn, coords


def test_fe_sets_partition_the_box(seg):
    box = (np.array(seg.shape[::-1]) - 1.0) * SPACING
    sets = fe_sets(seg.points, seg.tetrahedra, seg.material, seg.interfaces,
                   seg.interface_materials, box)
    elements = np.concatenate(list(sets.element_sets.values()))
    assert np.array_equal(np.sort(elements), np.arange(len(seg.tetrahedra)))
    _, _, boundary, _ = face_graph(seg.tetrahedra)
    # every boundary face on exactly one side, and the sides' areas are the box's faces
    assert sum(len(f) for f in sets.side_facets.values()) == len(boundary)
    p = seg.points
    for s, name in enumerate(BOX_SIDES):
        f = sets.side_facets[name]
        area = 0.5 * np.linalg.norm(np.cross(p[f[:, 1]] - p[f[:, 0]], p[f[:, 2]] - p[f[:, 0]]),
                                    axis=1)
        other = [a for a in range(3) if a != s // 2]
        assert area.sum() == pytest.approx(box[other[0]] * box[other[1]], rel=1e-12)
        normal = np.cross(p[f[:, 1]] - p[f[:, 0]], p[f[:, 2]] - p[f[:, 0]])[:, s // 2]
        assert np.all(normal < 0) if s % 2 == 0 else np.all(normal > 0)  # outward
    assert sum(len(f) for f in sets.interface_facets.values()) == len(seg.interfaces)


def test_fe_sets_refuse_a_hole(seg):
    keep = np.ones(len(seg.tetrahedra), bool)
    keep[np.argmax(seg.points[seg.tetrahedra].mean(axis=1)[:, 0])] = False  # one on x_max
    box = (np.array(seg.shape[::-1]) - 1.0) * SPACING
    with pytest.raises(ValueError, match="no side of the box"):
        fe_sets(seg.points, seg.tetrahedra[keep], seg.material[keep], seg.interfaces,
                seg.interface_materials, box)


@pytest.mark.parametrize("direction", [np.eye(3), np.diag([-1.0, -1.0, 1.0]),
                                       np.diag([-1.0, 1.0, 1.0]) @ _rotation((1, 2, 3), 0.6)])
def test_gmsh_reads_physical_groups(seg, tmp_path, direction):
    geom = ImageGeometry(origin=(1.0, 2.0, 3.0), spacing=SPACING, direction=direction)
    path = str(tmp_path / "part.msh")
    assert write_tetra_mesh(seg, path, geom)[0] == [path]
    groups, sicn, coords = _gmsh_groups(path)
    counts = np.bincount(seg.material)
    for k, n in enumerate(counts):
        assert groups[f"material_{k}"] == (3, n)
    pairs = np.unique(seg.interface_materials, axis=0)
    for a, b in pairs:
        n = int(np.all(seg.interface_materials == [a, b], axis=1).sum())
        assert groups[f"interface_{a}_{b}"] == (2, n)
    _, _, boundary, _ = face_graph(seg.tetrahedra)
    assert sum(groups[s][1] for s in BOX_SIDES) == len(boundary)
    assert len(groups) == len(counts) + len(pairs) + 6
    assert len(sicn) == len(seg.tetrahedra) and sicn.min() > 0  # none inverted, any direction
    pts, _ = world_tetrahedra(seg, geom)
    assert np.allclose(coords, pts, atol=1e-12)


def test_abaqus_and_xdmf_reopen(seg, tmp_path):
    import meshio

    inp, xdmf = str(tmp_path / "part.inp"), str(tmp_path / "part.xdmf")
    write_tetra_mesh(seg, inp, GEOM)
    write_tetra_mesh(seg, xdmf, GEOM)
    pts, tets = world_tetrahedra(seg, GEOM)
    a = meshio.read(inp)
    assert np.allclose(a.points, pts) and np.array_equal(a.cells_dict["tetra"], tets)
    for k in np.unique(seg.material):
        assert np.array_equal(np.sort(a.cell_sets[f"material_{k}"][0]),
                              np.flatnonzero(seg.material == k))
    assert set(BOX_SIDES) <= set(a.point_sets)
    text = open(inp).read()
    for k in np.unique(seg.material):
        assert f"*SOLID SECTION, ELSET=material_{k}, MATERIAL=material_{k}" in text
        assert f"*MATERIAL, NAME=material_{k}" in text
    x = meshio.read(xdmf)
    assert np.allclose(x.points, pts) and np.array_equal(x.cells_dict["tetra"], tets)
    assert np.array_equal(x.cell_data["material"][0], seg.material)
    assert np.allclose(x.cell_data["gray"][0], seg.gray)
    assert sorted(os.listdir(tmp_path)) == ["part.inp", "part.xdmf"]  # one file each


def test_failed_fe_write_leaves_nothing(seg, tmp_path, monkeypatch):
    import meshio

    def broken(*args, **kwargs):
        raise OSError("disk full")

    monkeypatch.setattr(meshio, "write", broken)
    with pytest.raises(OSError):
        write_tetra_mesh(seg, str(tmp_path / "part.msh"), GEOM)
    assert os.listdir(tmp_path) == []


def test_unwritable_fe_output(seg, tmp_path):
    with pytest.raises(InputError, match="does not exist"):
        write_tetra_mesh(seg, str(tmp_path / "missing" / "part.msh"), GEOM)


def _heat_solve(path, conductivity):
    """Steady heat conduction on the exported mesh: T = 0 on x_min, 1 on x_max, no flux
    elsewhere, conductivity per material. Returns the nodal temperatures, the element
    volumes, each element's conductivity and the heat flowing in through x_min and out
    through x_max (reactions of the assembled system)."""
    from skfem import Basis, BilinearForm, ElementTetP0, ElementTetP1, asm, condense, solve

    mesh = skfem.MeshTet.load(path)
    material = np.full(mesh.nelements, -1)
    for name, elements in mesh.subdomains.items():
        material[elements] = int(name.rsplit("_", 1)[1])
    assert material.min() >= 0
    kappa = np.asarray(conductivity)[material]
    basis = Basis(mesh, ElementTetP1())

    @BilinearForm
    def heat(u, v, w):
        return w.kappa * sum(u.grad[i] * v.grad[i] for i in range(3))

    stiffness = asm(heat, basis, kappa=basis.with_element(ElementTetP0()).interpolate(kappa))
    cold, hot = basis.get_dofs("x_min").all(), basis.get_dofs("x_max").all()
    temperature = np.zeros(basis.N)
    temperature[hot] = 1.0
    temperature = solve(*condense(stiffness, x=temperature, D=np.concatenate([cold, hot])))
    reaction = stiffness @ temperature
    volume = tetra_volumes(mesh.p.T, mesh.t.T)
    return temperature, volume, kappa, -reaction[cold].sum(), reaction[hot].sum()


@pytest.mark.parametrize("direction", [np.eye(3), np.diag([-1.0, 1.0, 1.0])])
def test_heat_conduction_on_exported_mesh(seg, tmp_path, direction):
    geom = ImageGeometry(origin=(1.0, 2.0, 3.0), spacing=SPACING, direction=direction)
    path = str(tmp_path / "part.msh")
    write_tetra_mesh(seg, path, geom)
    box = (np.array(seg.shape[::-1]) - 1.0) * SPACING
    length, area = box[0], box[1] * box[2]
    conductivity = [1.0, 10.0, 0.1, 50.0]
    temperature, volume, kappa, flux_in, flux_out = _heat_solve(path, conductivity)
    assert volume.min() > 0
    assert volume.sum() == pytest.approx(np.prod(box), rel=1e-12)
    assert temperature.min() >= -1e-9 and temperature.max() <= 1 + 1e-9  # maximum principle
    assert abs(flux_in - flux_out) <= 1e-6 * abs(flux_out)
    # the effective conductivity lies between the harmonic and the arithmetic means
    # (Wiener bounds; the FE solution is within them, its linear trial field giving the upper)
    k_eff = flux_out * length / area
    harmonic = volume.sum() / (volume / kappa).sum()
    arithmetic = (kappa * volume).sum() / volume.sum()
    assert harmonic < k_eff < arithmetic
    # one conductivity everywhere: the exact linear solution, and the flux k A / L
    temperature, _, _, _, flux_out = _heat_solve(path, [3.0] * 4)
    mesh = skfem.MeshTet.load(path)
    assert np.allclose(temperature, geom.to_index(mesh.p.T)[:, 0] * SPACING[0] / length, atol=1e-9)
    assert flux_out == pytest.approx(3.0 * area / length, rel=1e-9)
