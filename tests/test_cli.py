import json
import os
import subprocess
import sys

import numpy as np
import pytest

from ctseg.cli import main
from ctseg.filters import polydata_to_arrays, read_polydata
from ctseg.meshcheck import mesh_check_report

from conftest import disc_image, requires_rendering


@pytest.fixture()
def slice_files(tmp_path):
    img, truth = disc_image(64, noise=6.0)
    np.save(tmp_path / "slice.npy", img)
    np.save(tmp_path / "truth.npy", truth)
    return tmp_path


def test_mesh_command_writes_everything(slice_files, capsys):
    d = slice_files
    rc = main(["mesh", str(d / "slice.npy"), "-o", str(d / "m.vtp"), "--boundary", str(d / "b.vtp"),
               "--report", str(d / "r.json"), "--truth",
               str(d / "truth.npy"), "--sites", "150"])
    assert rc == 0
    out = capsys.readouterr().out
    assert "Dice per material" in out and "mesh checks: passed" in out
    pts, tri, arrays = polydata_to_arrays(read_polydata(d / "m.vtp"))
    assert set(arrays) >= {"material", "gray", "slice"} and len(tri) == len(arrays["material"])
    assert mesh_check_report(pts, tri)["ok"]
    report = json.loads((d / "r.json").read_text())
    for key in ("times_s", "cvt_energy", "lloyd_iterations", "graphcut_calls", "accuracy", "mesh_checks"):
        assert key in report
    assert report["accuracy"]["min_dice"] > 0.95
    assert report["n_sites"] == 150 and len(tri) == report["n_triangles"]
    b = read_polydata(d / "b.vtp")
    assert b.GetNumberOfLines() > 0 and b.GetCellData().GetArray("material_a") is not None


def test_materials_option(slice_files):
    d = slice_files
    assert main(["mesh", str(d / "slice.npy"), "-o", str(d / "m.vtp"), "--materials", "1", "-q"]) == 0
    _, _, arrays = polydata_to_arrays(read_polydata(d / "m.vtp"))
    assert set(arrays["material"].tolist()) == {0}


@pytest.mark.parametrize("args,message", [
    (["missing.npy", "-o", "m.vtp"], "no such file"),
    (["slice.npy", "-o", "m.abc"], "unknown output format"),
    (["slice.npy", "-o", "m.vtp", "--figure", "f.jpg"], "unknown output format"),
    (["slice.npy", "-o", "m.vtp", "--materials", "0"], "n_materials"),
    (["slice.npy", "-o", "m.vtp", "--sites", "2"], "n_sites"),
    (["slice.npy", "-o", "m.vtp", "--sites", "99999"], "n_sites"),
    (["slice.npy", "-o", "nowhere/m.vtp"], "does not exist"),
])
def test_errors_are_one_line_and_exit_2(slice_files, capsys, monkeypatch, args, message):
    monkeypatch.chdir(slice_files)
    assert main(["mesh"] + args) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("ctseg: error:") and message in err and "Traceback" not in err
    assert len(err.splitlines()) == 1
    assert not (slice_files / "m.vtp").exists()


def test_console_script_help():
    out = subprocess.run([sys.executable, "-m", "ctseg.cli", "mesh", "--help"], capture_output=True, text=True)
    assert out.returncode == 0 and "one per 128 pixels" in out.stdout


def test_volume_from_nrrd_to_ply_with_truth(tmp_path, capsys):
    """A volume file through the command: every slice meshed, one numbering, Dice over the
    volume; two worker processes."""
    import nrrd
    import pymeshlab

    from ctseg.phantoms import make_volume

    p = make_volume(5, 96, seed=2)
    nrrd.write(str(tmp_path / "v.nrrd"), p.image, {"spacings": [0.1, 0.1, 0.3]}, index_order="C")
    np.save(tmp_path / "t.npy", p.truth)
    rc = main(["mesh", str(tmp_path / "v.nrrd"), "-o", str(tmp_path / "v.ply"), "--sites", "350",
               "--jobs", "2", "--truth", str(tmp_path / "t.npy"),
               "--report", str(tmp_path / "r.json")])
    assert rc == 0
    report = json.loads((tmp_path / "r.json").read_text())
    assert report["n_slices"] == 5 and report["executor"] == "2 processes"
    dice = report["accuracy"]["dice"]
    assert report["n_materials"] == 4 and min(dice[0], dice[2], dice[3]) > 0.9 and dice[1] > 0.7
    ms = pymeshlab.MeshSet()
    ms.load_new_mesh(str(tmp_path / "v.ply"))
    assert ms.current_mesh().face_number() == report["n_triangles"] == report["mesh_checks"]["faces"]
    # z of the vertices: the slice positions, 0.3 mm apart
    z = np.unique(np.round(ms.current_mesh().vertex_matrix()[:, 2], 9))
    np.testing.assert_allclose(z, 0.3 * np.arange(5))
    assert "slices along z" in capsys.readouterr().out


def test_interrupt_leaves_no_partial_output(tmp_path, monkeypatch, capsys):
    import ctseg.volume

    calls = []

    def interrupted(image, params, keep_maps=False):
        calls.append(1)
        if len(calls) == 3:
            raise KeyboardInterrupt
        return real(image, params, keep_maps)

    real = ctseg.volume._segment_slice
    monkeypatch.setattr(ctseg.volume, "_segment_slice", interrupted)
    vol = np.random.default_rng(0).random((4, 16, 16))
    np.save(tmp_path / "v.npy", vol)
    rc = main(["mesh", str(tmp_path / "v.npy"), "-o", str(tmp_path / "m.vtp"), "--jobs", "1",
               "--report", str(tmp_path / "r.json")])
    assert rc == 130 and "interrupted" in capsys.readouterr().err
    assert os.listdir(tmp_path) == ["v.npy"]


@requires_rendering
def test_figure_of_a_slice_and_of_a_volume(slice_files):
    """The six panels, rendered offscreen; a volume's figure shows its middle slice."""
    from ctseg.filters.readers import read_image

    d = slice_files
    assert main(["mesh", str(d / "slice.npy"), "-o", str(d / "m.vtp"), "--sites", "150",
                 "--figure", str(d / "f.png"), "-q"]) == 0
    fig, _ = read_image(d / "f.png")
    vol = np.stack([np.load(d / "slice.npy")] * 3)
    np.save(d / "v.npy", vol)
    assert main(["mesh", str(d / "v.npy"), "-o", str(d / "v.vtp"), "--sites", "150", "--jobs", "1",
                 "--figure", str(d / "fv.png"), "-q"]) == 0
    figv, _ = read_image(d / "fv.png")
    assert fig.shape == figv.shape and fig.shape[1] > fig.shape[0] > 300
