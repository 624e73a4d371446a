import json
import subprocess
import sys

import numpy as np
import pytest

from ctseg.cli import main
from ctseg.filters import polydata_to_arrays, read_polydata
from ctseg.meshcheck import mesh_check_report

from conftest import disc_image


@pytest.fixture()
def slice_files(tmp_path):
    img, truth = disc_image(64, noise=6.0)
    np.save(tmp_path / "slice.npy", img)
    np.save(tmp_path / "truth.npy", truth)
    return tmp_path


def test_mesh_command_writes_everything(slice_files, capsys):
    d = slice_files
    rc = main(["mesh", str(d / "slice.npy"), "-o", str(d / "m.vtp"), "--boundary", str(d / "b.vtp"),
               "--report", str(d / "r.json"), "--figure", str(d / "f.png"), "--truth",
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
    assert (d / "f.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_materials_option(slice_files):
    d = slice_files
    assert main(["mesh", str(d / "slice.npy"), "-o", str(d / "m.vtp"), "--materials", "1", "-q"]) == 0
    _, _, arrays = polydata_to_arrays(read_polydata(d / "m.vtp"))
    assert set(arrays["material"].tolist()) == {0}


@pytest.mark.parametrize("args,message", [
    (["missing.npy", "-o", "m.vtp"], "no such file"),
    (["slice.npy", "-o", "m.stl"], "unknown output format"),
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
