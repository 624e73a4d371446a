"""``ctseg mesh --mode 3d``: a volume file to tetrahedra, closed surfaces, interfaces, report,
figure and Dice, in the file's world geometry; and the inputs and options it refuses."""
import json
import os

import numpy as np
import pytest

from ctseg.cli import main
from ctseg.filters import read_image
from ctseg.filters.convert3d import grid_to_arrays
from ctseg.filters.writers3d import read_unstructured_grid
from ctseg.phantoms import make_volume
from ctseg.tetrahedra import tetra_volumes

from conftest import requires_rendering

# LPS-like: x and y flipped, then one more flip of z (det -1), tilted about z
_C, _S = np.cos(0.3), np.sin(0.3)
DIRECTION = np.array([[_C, -_S, 0], [_S, _C, 0], [0, 0, 1.0]]) @ np.diag([-1.0, -1.0, -1.0])
SPACING = np.array([0.1, 0.1, 0.3])


def _write_nrrd(path, image, direction=DIRECTION, spacing=SPACING, origin=(12.0, -3.0, 40.0)):
    import nrrd

    # NRRD's space directions: one row per axis, x (fastest) first
    header = {"space": "left-posterior-superior", "space origin": np.asarray(origin, float),
              "space directions": (direction * spacing).T}
    nrrd.write(str(path), image, header, index_order="C")


@pytest.fixture(scope="module")
def volume_files(tmp_path_factory):
    d = tmp_path_factory.mktemp("vol3d")
    p = make_volume(12, 28, seed=2)
    _write_nrrd(d / "v.nrrd", p.image)
    np.save(d / "t.npy", p.truth)
    np.save(d / "v.npy", p.image)
    return d


@requires_rendering
def test_3d_command_writes_everything(volume_files, tmp_path, capsys):
    d = volume_files
    rc = main(["mesh", str(d / "v.nrrd"), "--mode", "3d", "-o", str(tmp_path / "m.vtu"),
               "--surfaces", str(tmp_path / "s.vtp"), "--report", str(tmp_path / "r.json"),
               "--figure", str(tmp_path / "f.png"), "--truth", str(d / "t.npy"),
               "--sites", "300"])
    assert rc == 0
    out = capsys.readouterr().out
    for word in ("tetrahedra", "materials", "interface triangles", "levels (0-255):", "surfaces: material 0",
                 "quality: min dihedral", "mesh checks: passed", "Dice per material"):
        assert word in out, (word, out)
    report = json.loads((tmp_path / "r.json").read_text())
    for key in ("times_s", "peak_memory_mib", "cvt_energy", "lloyd_iterations",
                "element_quality", "surfaces", "mesh_checks", "accuracy", "parameters",
                "surfaces_output", "figure"):
        assert key in report, key
    assert report["parameters"]["volume"]["mode"] == "3d" and report["n_sites"] == 300
    assert set(report["times_s"]) >= {"density", "cvt", "tetrahedra", "graphcut", "surfaces"}
    assert all(s["ok"] for s in report["mesh_checks"]["surfaces"])
    assert report["accuracy"]["dice"][0] > 0.9
    # world geometry: the file's; every tetrahedron positive there; the box filled
    _, geom = read_image(str(d / "v.nrrd"))
    assert np.linalg.det(geom.direction) < 0
    pts, tets, arrays = grid_to_arrays(read_unstructured_grid(tmp_path / "m.vtu"))
    assert len(tets) == report["n_tetrahedra"] and arrays["material"].max() == report["n_materials"] - 1
    vol = tetra_volumes(pts, tets)
    box = (np.array([28, 28, 12]) - 1) * SPACING
    assert vol.min() > 0
    np.testing.assert_allclose(vol.sum(), np.prod(box), rtol=1e-9)
    ijk = geom.to_index(pts)
    np.testing.assert_allclose(ijk.min(axis=0), 0, atol=1e-9)
    np.testing.assert_allclose(ijk.max(axis=0), [27, 27, 11], atol=1e-9)
    from ctseg.filters import polydata_to_arrays, read_polydata

    _, tri, side = polydata_to_arrays(read_polydata(tmp_path / "s.vtp"))
    assert len(tri) == report["n_interface_triangles"] and np.all(side["material_a"] < side["material_b"])
    assert os.path.getsize(tmp_path / "f.png") > 10_000
    assert sorted(os.listdir(tmp_path)) == ["f.png", "m.vtu", "r.json", "s.vtp"]


@pytest.mark.parametrize("ext", [".vtp", ".stl", ".ply", ".obj"])
def test_3d_surface_formats(volume_files, tmp_path, ext):
    assert main(["mesh", str(volume_files / "v.npy"), "--mode", "3d", "-o",
                 str(tmp_path / f"m{ext}"), "--sites", "150", "--report",
                 str(tmp_path / "r.json"), "-q"]) == 0
    report = json.loads((tmp_path / "r.json").read_text())
    k = report["n_materials"]
    expected = {".vtp": ["m.vtp"], ".ply": ["m.ply"], ".obj": ["m.mtl", "m.obj"],
                ".stl": [f"m_material{m}.stl" for m in range(k)]}[ext]
    assert sorted(os.listdir(tmp_path)) == sorted(expected + ["r.json"])
    assert [os.path.basename(p) for p in report["outputs"]] == sorted(expected, key=lambda n: n.endswith(".mtl"))


@pytest.mark.parametrize("ext", [".msh", ".inp", ".xdmf"])
def test_3d_fe_formats(volume_files, tmp_path, ext):
    """The pipeline's own mesh (world geometry with a flipped direction) through the CLI:
    each FE file reopens with its elements, one set per material, none inverted."""
    import meshio

    out = str(tmp_path / f"m{ext}")
    assert main(["mesh", str(volume_files / "v.nrrd"), "--mode", "3d", "-o", out, "--sites",
                 "150", "--report", str(tmp_path / "r.json"), "-q"]) == 0
    report = json.loads((tmp_path / "r.json").read_text())
    assert sorted(os.listdir(tmp_path)) == sorted([f"m{ext}", "r.json"])
    mesh = meshio.read(out)
    tets = mesh.cells_dict["tetra"]
    assert len(tets) == report["n_tetrahedra"]
    assert tetra_volumes(mesh.points, tets).min() > 0
    if ext == ".msh":
        names = {name for name, (_, dim) in mesh.field_data.items() if dim == 3}
        assert names == {f"material_{k}" for k in range(report["n_materials"])}
    elif ext == ".inp":
        assert set(mesh.cell_sets) == {f"material_{k}" for k in range(report["n_materials"])}
    else:
        assert np.unique(mesh.cell_data["material"][0]).tolist() == list(range(report["n_materials"]))


def test_report_parameters_reproduce_the_run(volume_files, tmp_path):
    cmd = ["mesh", str(volume_files / "v.npy"), "-q"]
    assert main(cmd + ["--mode", "3d", "--sites", "120", "-o", str(tmp_path / "a.vtu"),
                       "--report", str(tmp_path / "a.json")]) == 0
    assert main(cmd + ["--params", str(tmp_path / "a.json"), "-o", str(tmp_path / "b.vtu")]) == 0
    assert (tmp_path / "a.vtu").read_bytes() == (tmp_path / "b.vtu").read_bytes()


def test_constant_volume_is_one_material_filling_the_box(tmp_path):
    """As in 2D (tests/test_bad_input.py), a constant input is valid: one material, whose
    closed surface is the box."""
    np.save(tmp_path / "c.npy", np.full((5, 9, 11), 7.0))
    assert main(["mesh", str(tmp_path / "c.npy"), "--mode", "3d", "-o", str(tmp_path / "c.vtu"),
                 "--report", str(tmp_path / "r.json"), "-q"]) == 0
    report = json.loads((tmp_path / "r.json").read_text())
    assert report["n_materials"] == 1 and report["n_interface_triangles"] == 0
    np.testing.assert_allclose(report["surfaces"][0]["enclosed_volume"], 10 * 8 * 4, rtol=1e-9)


# ------------------------------------------------------------------- refused: one line, exit 2
def _refused(tmp_path, capsys, args, *words):
    before = set(os.listdir(tmp_path))
    rc = main(["mesh"] + [str(a) for a in args])
    err = capsys.readouterr().err.strip()
    assert rc == 2, err
    assert err.startswith("ctseg: error:") and len(err.splitlines()) == 1, err
    assert "Traceback" not in err
    for word in words:
        assert word in err, (word, err)
    assert set(os.listdir(tmp_path)) == before, "an output was written"


def _vol(shape=(6, 12, 14)):
    return make_volume(shape[0], 12, seed=1).image[:, :shape[1], :shape[2]]


@pytest.mark.parametrize("name,array,words", [
    ("one_slice", _vol()[:1], ["in.npy", "3D mode needs a volume", "2 voxels along every axis"]),
    ("one_row", _vol()[:, :1, :], ["in.npy", "3D mode needs a volume", "along y", "--axis y"]),
    ("one_column", _vol()[:, :, :1], ["in.npy", "3D mode needs a volume", "along x", "--axis x"]),
    ("nan", np.where(np.arange(6 * 12 * 12).reshape(6, 12, 12) == 100, np.nan, 1.0),
     ["NaN or infinite", "slice 0"]),
    ("inf", np.full((4, 8, 8), np.inf), ["NaN or infinite"]),
])
def test_refused_volumes(tmp_path, capsys, name, array, words):
    np.save(tmp_path / "in.npy", array)
    _refused(tmp_path, capsys, [tmp_path / "in.npy", "--mode", "3d", "-o", tmp_path / "m.vtu"],
             *words)


def test_the_axis_the_thin_volume_message_names_works_in_slices_mode(tmp_path):
    np.save(tmp_path / "in.npy", _vol()[:, :1, :])
    assert main(["mesh", str(tmp_path / "in.npy"), "--axis", "y", "-o", str(tmp_path / "m.vtp"),
                 "--sites", "20", "-q"]) == 0
    assert os.path.getsize(tmp_path / "m.vtp") > 0


def test_a_failure_after_the_mesh_leaves_no_output(volume_files, tmp_path, monkeypatch):
    import ctseg.filters.figure3d as figure3d
    from ctseg.filters.job3d import segment_and_write_3d
    from ctseg.params import resolve

    def broken(*args, **kwargs):
        raise RuntimeError("no OpenGL")

    monkeypatch.setattr(figure3d, "render_volume_figure", broken)
    image, geometry = read_image(volume_files / "v.nrrd")
    with pytest.raises(RuntimeError, match="no OpenGL"):
        segment_and_write_3d(image, geometry, resolve(mode="3d", n_sites=200), str(tmp_path / "m.vtu"),
                             surfaces=str(tmp_path / "s.vtp"), figure=str(tmp_path / "f.png"))
    assert os.listdir(tmp_path) == []


def test_too_large_for_memory_is_refused_before_the_work(tmp_path, capsys, monkeypatch):
    import ctseg.resources

    np.save(tmp_path / "in.npy", _vol())
    monkeypatch.setattr(ctseg.resources, "available_bytes", lambda: 2 ** 16)  # 64 KiB free
    _refused(tmp_path, capsys, [tmp_path / "in.npy", "--mode", "3d", "-o", tmp_path / "m.msh"],
             "6 x 12 x 12 volume in 3D needs about", "GiB of memory", "slices mode")


@pytest.mark.parametrize("spacing", [(0.1, -0.1, 0.3), (0.1, 0.0, 0.3)])
def test_refused_spacing(tmp_path, capsys, spacing):
    import nrrd

    nrrd.write(str(tmp_path / "v.nrrd"), _vol(), {"spacings": list(spacing)}, index_order="C")
    _refused(tmp_path, capsys, [tmp_path / "v.nrrd", "--mode", "3d", "-o", tmp_path / "m.vtu"],
             "v.nrrd", "spacing")


@pytest.mark.parametrize("extra,words", [
    (["-o", "m.abc"], ["m.abc", "unknown output format", ".vtu"]),
    (["-o", "m.mlp"], ["unknown output format"]),
    (["-o", "m.unv"], ["m.unv", "unknown output format", ".msh", ".inp", ".xdmf"]),
    (["-o", "nowhere/m.msh"], ["does not exist"]),
    (["-o", "in.npy/m.inp"], ["does not exist"]),
    (["-o", "/proc/m.msh"], ["/proc/m.msh", "not writable"]),  # refused even to root
    (["-o", "m.vtu", "--surfaces", "/proc/s.vtp"], ["/proc/s.vtp", "not writable"]),
    (["-o", "nowhere/m.vtu"], ["does not exist"]),
    (["-o", "sub"], ["is a folder"]),
    (["-o", "in.npy/m.vtu"], ["does not exist"]),
    (["-o", "m.vtu", "--boundary", "b.vtp"], ["--boundary", "--surfaces"]),
    (["-o", "m.vtu", "--surfaces", "s.vtu"], ["s.vtu", "unknown output format"]),
    (["-o", "m.vtu", "--figure", "f.jpg"], ["f.jpg", "unknown output format"]),
    (["-o", "m.vtu", "--report", "r.txt"], ["r.txt", "unknown output format"]),
    (["-o", "m.vtu", "--truth", "short.npy"], ["short.npy", "truth shape"]),
    (["-o", "m.vtu", "--sites", "99999"], ["n_sites"]),
])
def test_refused_outputs_and_options(tmp_path, capsys, monkeypatch, extra, words):
    np.save(tmp_path / "in.npy", _vol())
    np.save(tmp_path / "short.npy", np.zeros((5, 12, 14), np.uint8))
    os.mkdir(tmp_path / "sub")
    monkeypatch.chdir(tmp_path)
    _refused(tmp_path, capsys, ["in.npy", "--mode", "3d"] + extra, *words)


def test_surfaces_is_refused_in_slices_mode(tmp_path, capsys, monkeypatch):
    np.save(tmp_path / "in.npy", _vol())
    monkeypatch.chdir(tmp_path)
    _refused(tmp_path, capsys, ["in.npy", "-o", "m.vtp", "--mode", "slices", "--surfaces", "s.vtp"],
             "--surfaces", "--mode 3d", "--boundary")


@pytest.mark.skipif(hasattr(os, "geteuid") and os.geteuid() == 0,
                    reason="root may write into a read-only folder")
def test_unwritable_folder(tmp_path, capsys):
    np.save(tmp_path / "in.npy", _vol())
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    try:
        _refused(tmp_path, capsys, [tmp_path / "in.npy", "--mode", "3d", "-o", ro / "m.vtu"],
                 "not writable")
        assert os.listdir(ro) == []
    finally:
        ro.chmod(0o755)


def test_levels_line_says_where_the_levels_came_from():
    from ctseg.filters.job3d import _levels_line

    line = _levels_line({"method": "flat_voxels", "homogeneous_added_255": [41.6]},
                        [16.6, 41.6, 71.9, 254.0])
    assert line.startswith("levels (0-255): 16.6, 41.6, 71.9, 254.0 from the flat voxels")
    assert "41.6 shown only by the homogeneous tetrahedra" in line
    assert "homogeneous" not in _levels_line({"method": "tetrahedra"}, [20.0, 80.0])


# ------------------------------------------------------------------- mode auto, the default
def _memory_for_slices_only(monkeypatch, vol):
    """One byte less available than 3D mode needs for ``vol``."""
    import ctseg.resources

    monkeypatch.setattr(ctseg.resources, "available_bytes",
                        lambda: vol.size * ctseg.resources.VOLUME_3D_BYTES_PER_VOXEL - 1)


def test_auto_mode_meshes_a_volume_in_3d_and_falls_back_to_slices(tmp_path, capsys, monkeypatch):
    """Without --mode a volume becomes tetrahedra; where 3D mode would not fit in the memory
    available but slices do, it goes slice by slice and says why, after the work."""
    from ctseg.volume import volume_mode

    vol = _vol((4, 12, 12)).astype(np.float32)
    np.save(tmp_path / "in.npy", vol)
    assert main(["mesh", str(tmp_path / "in.npy"), "-o", str(tmp_path / "m.vtu"), "--sites", "30",
                 "--report", str(tmp_path / "r.json"), "-q"]) == 0
    assert json.loads((tmp_path / "r.json").read_text())["mode"] == "3d"
    _, tets, _ = grid_to_arrays(read_unstructured_grid(tmp_path / "m.vtu"))
    assert tets.shape[1] == 4
    _memory_for_slices_only(monkeypatch, vol)
    assert volume_mode(vol.shape)[0] == "slices" and volume_mode(vol.shape, "3d") == ("3d", "")
    rc = main(["mesh", str(tmp_path / "in.npy"), "-o", str(tmp_path / "m.vtp"), "--sites", "30",
               "--jobs", "1", "--report", str(tmp_path / "r2.json")])
    err = capsys.readouterr().err
    report = json.loads((tmp_path / "r2.json").read_text())
    assert rc == 0 and report["n_slices"] == 4 and report["mode"] == "slices"
    assert "mode auto: slices, 3D mode would need about" in err and "mode auto" in report["mode_note"]


@pytest.mark.parametrize("shape,mode", [((12, 14), "slices"), ((1, 12, 14), "slices"),
                                        ((6, 1, 14), "slices"), ((2, 2, 2), "3d")])
def test_auto_mode_by_shape(shape, mode):
    from ctseg.volume import volume_mode

    assert volume_mode(shape) == (mode, "")
    assert volume_mode(shape, "slices") == ("slices", "") and volume_mode(shape, "3d") == ("3d", "")


@pytest.mark.parametrize("extra,named,output", [(["--boundary", "b.vtp"], "--boundary", "m.vtp"),
                                                (["-o", "m.mlp"], ".mlp output", "m.mlp")])
def test_auto_mode_takes_slices_for_options_only_slices_mode_has(tmp_path, capsys, monkeypatch, extra, named,
                                                                 output):
    """--boundary and a MeshLab project are slices mode's: under mode auto they choose it
    (and say so), where --mode 3d refuses them."""
    monkeypatch.chdir(tmp_path)
    np.save("in.npy", _vol((4, 12, 12)).astype(np.float32))
    out = [] if "-o" in extra else ["-o", output]
    assert main(["mesh", "in.npy", "--sites", "30", "--jobs", "1", "--report", "r.json"] + out + extra) == 0
    report = json.loads((tmp_path / "r.json").read_text())
    assert report["mode"] == "slices" and report["parameters"]["volume"]["mode"] == "slices"
    assert f"for {named} (slices mode's" in report["mode_note"]
    assert "mode auto: slices" in capsys.readouterr().err
    assert (tmp_path / output).is_file() and not (tmp_path / f"{output}.ctseg-partial").exists()


@pytest.mark.parametrize("extra", [["--axis", "y"], ["--set", "axis=x"], ["--resume"]])
def test_auto_mode_stays_3d_for_settings_3d_mode_ignores(tmp_path, capsys, monkeypatch, extra):
    """A slice axis (like --jobs) and a --resume with nothing to resume leave auto in 3D."""
    monkeypatch.chdir(tmp_path)
    np.save("in.npy", _vol((4, 12, 12)).astype(np.float32))
    assert main(["mesh", "in.npy", "--sites", "30", "-o", "m.vtu", "--report", "r.json", "-q"] + extra) == 0
    report = json.loads((tmp_path / "r.json").read_text())
    assert report["mode"] == "3d" and "mode_note" not in report


def test_auto_fallback_names_itself_when_it_refuses_a_3d_output(tmp_path, capsys, monkeypatch):
    """Where auto went to slices (memory), a 3D-only output is refused with the reason."""
    vol = _vol((4, 12, 12)).astype(np.float32)
    np.save(tmp_path / "in.npy", vol)
    _memory_for_slices_only(monkeypatch, vol)
    for extra in (["-o", str(tmp_path / "m.msh")],
                  ["-o", str(tmp_path / "m.vtp"), "--surfaces", str(tmp_path / "s.vtp")]):
        assert main(["mesh", str(tmp_path / "in.npy")] + extra) == 2
        err = capsys.readouterr().err
        assert "mode auto: slices, 3D mode would need about" in err and len(err.strip().splitlines()) == 1
    assert os.listdir(tmp_path) == ["in.npy"]


def test_resume_after_auto_fell_back_to_slices(tmp_path, capsys, monkeypatch):
    """An auto run that went slice by slice (3D mode did not fit) and was interrupted goes on
    from its finished slices with --resume, even once 3D mode would fit."""
    import ctseg.resources
    import ctseg.volume

    vol = make_volume(4, 40, seed=1).image
    np.save(tmp_path / "v.npy", vol)
    calls, real = [], ctseg.volume._segment_slice

    def interrupted(*args):
        calls.append(1)
        if len(calls) == 3:
            raise KeyboardInterrupt
        return real(*args)

    cmd = ["mesh", str(tmp_path / "v.npy"), "-o", str(tmp_path / "m.vtp"), "--jobs", "1",
           "--sites", "60", "--report", str(tmp_path / "r.json")]
    enough = ctseg.resources.available_bytes
    _memory_for_slices_only(monkeypatch, vol)
    monkeypatch.setattr(ctseg.volume, "_segment_slice", interrupted)
    assert main(cmd) == 130
    err = capsys.readouterr().err
    assert "2 finished slice(s)" in err and "mode auto: slices, 3D mode would need" in err
    monkeypatch.setattr(ctseg.volume, "_segment_slice", real)
    monkeypatch.setattr(ctseg.resources, "available_bytes", enough)
    assert main(cmd + ["--resume", "-q"]) == 0
    report = json.loads((tmp_path / "r.json").read_text())
    assert report["mode"] == "slices" and report["resumed_slices"] == 2
    assert sorted(os.listdir(tmp_path)) == ["m.vtp", "r.json", "v.npy"]


@pytest.mark.parametrize("thin", [0, 1, 2])
@pytest.mark.parametrize("mode", ["auto", "slices"])
def test_a_thin_volume_is_sliced_across_its_thin_axis(thin, mode):
    """A volume 1 voxel thin along any axis is one slice across that axis, whatever slice
    axis was asked for (slices along another would be 1 voxel wide)."""
    from ctseg.volume import segment_array

    vol = np.moveaxis(_vol((3, 12, 14))[:1], 0, thin)
    vseg = segment_array(vol, mode=mode, axis="zyx"[(thin + 1) % 3], n_sites=30, n_jobs=1)
    assert vseg.diagnostics["axis"] == "zyx"[thin] and len(vseg.slices) == 1
    assert vseg.diagnostics["parameters"]["volume"]["axis"] == "zyx"[thin]
    assert vseg.slices[0].diagnostics["image_shape"] == [n for n in vol.shape if n > 1]


def test_command_slices_a_thin_volume_across_its_thin_axis(tmp_path):
    np.save(tmp_path / "in.npy", _vol((3, 12, 14))[:, :1, :])
    assert main(["mesh", str(tmp_path / "in.npy"), "-o", str(tmp_path / "m.vtp"), "--sites", "20",
                 "--report", str(tmp_path / "r.json"), "-q"]) == 0
    report = json.loads((tmp_path / "r.json").read_text())
    assert report["axis"] == "y" and report["n_slices"] == 1


def test_mode_3d_refuses_a_single_slice_as_a_slice():
    from ctseg.errors import InputError
    from ctseg.volume import segment_array

    with pytest.raises(InputError, match="single 12 x 12 slice; 3D mode needs a volume"):
        segment_array(_vol((3, 12, 12))[0], mode="3d")
