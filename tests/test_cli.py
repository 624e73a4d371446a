import json
import os
import subprocess
import sys

import numpy as np
import pytest

import ctseg
from ctseg.cli import main
from ctseg.filters import polydata_to_arrays, read_polydata
from ctseg.meshcheck import mesh_check_report

from ctseg.phantoms import make_volume

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


def test_streak_correction_option(tmp_path):
    # a simulated slice with steel: corrected by default (gray values change), not with the flag
    from ctseg.phantoms import make_phantom
    p = make_phantom(96, seed=0)
    np.save(tmp_path / "s.npy", p.image)
    grays = {}
    for flag in ([], ["--no-streak-correction"]):
        name = "off" if flag else "on"
        assert main(["mesh", str(tmp_path / "s.npy"), "-o", str(tmp_path / f"{name}.vtp"),
                     "--report", str(tmp_path / f"{name}.json"), "--sites", "200", "-q"] + flag) == 0
        report = json.loads((tmp_path / f"{name}.json").read_text())
        grays[name] = polydata_to_arrays(read_polydata(tmp_path / f"{name}.vtp"))[2]["gray"]
        if flag:
            assert report["streak_correction"] is None
        else:
            assert report["streak_correction"]["weight"] > 0
            assert "streak_correction" in report["times_s"]
    assert not np.array_equal(grays["on"], grays["off"])


def test_blur_correction_option(tmp_path):
    # on by default (the fitted blur and its time in the report), off with the flag; the
    # written gray is the measured one either way
    from ctseg.phantoms import make_phantom
    np.save(tmp_path / "s.npy", make_phantom(96, seed=0).image)
    reports, grays = {}, {}
    for name, flag in (("on", []), ("off", ["--no-blur-correction"])):
        assert main(["mesh", str(tmp_path / "s.npy"), "-o", str(tmp_path / f"{name}.vtp"),
                     "--report", str(tmp_path / f"{name}.json"), "--sites", "200", "-q",
                     "--no-subpixel-boundary"] + flag) == 0  # which moves vertices
        reports[name] = json.loads((tmp_path / f"{name}.json").read_text())
        grays[name] = polydata_to_arrays(read_polydata(tmp_path / f"{name}.vtp"))[2]["gray"]
    # the simulator's blur (0.6 px detector blur, filtered back-projection) fits at 0.8-0.95 px
    # on 512 px slices
    assert 0.5 < reports["on"]["blur_px"] < 1.3 and "blur_correction" in reports["on"]["times_s"]
    assert reports["off"]["blur_px"] is None and "blur_correction" not in reports["off"]["times_s"]
    assert np.array_equal(grays["on"], grays["off"])


def test_materials_option(slice_files):
    d = slice_files
    assert main(["mesh", str(d / "slice.npy"), "-o", str(d / "m.vtp"), "--materials", "1", "-q"]) == 0
    _, _, arrays = polydata_to_arrays(read_polydata(d / "m.vtp"))
    assert set(arrays["material"].tolist()) == {0}


@pytest.mark.parametrize("args,message", [
    (["missing.npy", "-o", "m.vtp"], "no such file"),
    (["slice.npy", "-o", "m.abc"], "unknown output format"),
    (["slice.npy", "-o", "m.vtp", "--figure", "f.jpg"], "unknown output format"),
    (["slice.npy", "-o", "m.vtp", "--materials", "-2"], "n_materials"),
    (["slice.npy", "-o", "m.vtp", "--set", "lamda=3"], "did you mean 'lam'"),
    (["slice.npy", "-o", "m.vtp", "--params", "missing.json"], "--params"),
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
    # cwd: `python -m` puts the working directory first on sys.path, and a checkout's
    # ctseg/ folder is not the installed package (ctseg.filters lives in filters/)
    out = subprocess.run([sys.executable, "-m", "ctseg.cli", "mesh", "--help"], capture_output=True,
                         text=True, cwd=os.path.dirname(os.path.abspath(__file__)))
    assert out.returncode == 0 and "--set NAME=VALUE" in out.stdout and "n_sites" in out.stdout


def test_params_lists_every_parameter_and_round_trips(slice_files, capsys, monkeypatch):
    """`ctseg params` names every spec parameter; a report's parameters, given back with
    --params, reproduce the run; --set and the named options override them."""
    from ctseg.params import SPECS, SegmentParams

    assert main(["params"]) == 0
    table = capsys.readouterr().out
    assert all(name in table for name in SPECS)
    assert main(["params", "--json"]) == 0
    assert SegmentParams.from_dict(json.loads(capsys.readouterr().out)) == SegmentParams()
    monkeypatch.chdir(slice_files)
    assert main(["mesh", "slice.npy", "-o", "a.vtp", "--sites", "60", "--set", "lam=50",
                 "--set", "init=random", "--report", "a.json", "-q"]) == 0
    used = json.loads((slice_files / "a.json").read_text())["parameters"]
    assert used["graphcut"]["lam"] == 50.0 and used["sites"]["init"] == "random"
    assert used["sites"]["n_sites"] == 60
    assert main(["mesh", "slice.npy", "-o", "b.vtp", "--params", "a.json", "-q"]) == 0
    assert (slice_files / "a.vtp").read_bytes() == (slice_files / "b.vtp").read_bytes()


def test_volume_from_nrrd_to_ply_with_truth(tmp_path, capsys):
    """A volume file through the command: every slice meshed, one numbering, Dice over the
    volume; two worker processes."""
    import nrrd
    import pymeshlab

    from ctseg.phantoms import make_volume

    p = make_volume(5, 96, seed=2)
    nrrd.write(str(tmp_path / "v.nrrd"), p.image, {"spacings": [0.1, 0.1, 0.3]}, index_order="C")
    np.save(tmp_path / "t.npy", p.truth)
    rc = main(["mesh", str(tmp_path / "v.nrrd"), "-o", str(tmp_path / "v.ply"), "--mode", "slices", "--sites", "350",
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


def test_interrupt_leaves_no_partial_output_and_resume_finishes(tmp_path, monkeypatch, capsys):
    """Ctrl-C in the third slice: no output file, the two finished slices kept; --resume
    computes only the rest and writes the same bytes as an uninterrupted run."""
    import ctseg.volume

    calls = []
    real = ctseg.volume._segment_slice

    def interrupted(image, params, extra, keep_maps=False):
        calls.append(1)
        if len(calls) == 3:
            raise KeyboardInterrupt
        return real(image, params, extra, keep_maps)

    vol = make_volume(4, 48, seed=1).image
    np.save(tmp_path / "v.npy", vol)
    cmd = ["mesh", str(tmp_path / "v.npy"), "-o", str(tmp_path / "m.vtp"), "--mode", "slices", "--jobs", "1",
           "--sites", "60", "--report", str(tmp_path / "r.json")]
    monkeypatch.setattr(ctseg.volume, "_segment_slice", interrupted)
    assert main(cmd) == 130
    err = capsys.readouterr().err
    assert "interrupted" in err and "2 finished slice(s)" in err and "--resume" in err
    assert sorted(os.listdir(tmp_path)) == ["m.vtp.ctseg-partial", "v.npy"]
    monkeypatch.setattr(ctseg.volume, "_segment_slice", real)
    assert main(cmd + ["--resume", "-q"]) == 0
    report = json.loads((tmp_path / "r.json").read_text())
    assert report["resumed_slices"] == 2 and not (tmp_path / "m.vtp.ctseg-partial").exists()
    resumed = (tmp_path / "m.vtp").read_bytes()
    assert main(cmd + ["-q"]) == 0  # afresh
    assert (tmp_path / "m.vtp").read_bytes() == resumed


def test_resume_refuses_slices_of_other_parameters(tmp_path, capsys):
    from ctseg.volume import segment_volume

    from ctseg.cli import checkpoint_folder

    vol = make_volume(3, 40, seed=2).image
    np.save(tmp_path / "v.npy", vol)
    segment_volume(vol, mode="slices", n_sites=50, checkpoint=checkpoint_folder(tmp_path / "m.vtp"))
    assert main(["mesh", str(tmp_path / "v.npy"), "-o", str(tmp_path / "m.vtp"), "--mode", "slices", "--jobs", "1",
                 "--sites", "60", "--resume"]) == 2
    err = capsys.readouterr().err
    assert "differs in: n_sites" in err and len(err.strip().splitlines()) == 1


def test_real_sigint_to_the_command(tmp_path):
    """Ctrl-C at a terminal (SIGINT to the whole process group, workers included) during a
    two-process volume job: exit 130, one message, no output, the finished slices kept."""
    import signal
    import time

    vol = make_volume(64, 128, seed=3).image  # long enough (seconds) to interrupt mid-run
    np.save(tmp_path / "v.npy", vol)
    proc = subprocess.Popen([sys.executable, "-m", "ctseg.cli", "mesh", str(tmp_path / "v.npy"),
                             "-o", str(tmp_path / "m.vtp"), "--mode", "slices", "--jobs", "2", "--sites", "300"],
                            stderr=subprocess.PIPE, text=True, start_new_session=True,
                            cwd=tmp_path,  # the installed ctseg, not a checkout's folder
                            # as from a terminal: a shell that runs this suite in the
                            # background (nohup, CI) makes its children ignore SIGINT
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    folder = tmp_path / "m.vtp.ctseg-partial"
    deadline = time.time() + 60
    while time.time() < deadline and not (folder.exists() and any(
            f.startswith("slice_") for f in os.listdir(folder))):
        time.sleep(0.05)
    os.killpg(proc.pid, signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    assert "interrupted" in err and "--resume" in err and "Traceback" not in err, err
    assert len(err.strip().splitlines()) == 1, err
    assert not (tmp_path / "m.vtp").exists()
    assert not [f for f in os.listdir(tmp_path) if f.startswith(".ctseg-")]


def test_per_material_files_left_by_an_earlier_run_are_named(slice_files, capsys):
    """A run writing m_material0.stl and m_material1.stl into a folder that still holds an
    earlier run's m_material2.stl (and a m_material_notes.stl that is not ours) names the
    stale one in its summary, and leaves every file where it was."""
    d = slice_files
    (d / "m_material2.stl").write_text("old")
    (d / "m_material_notes.stl").write_text("mine")
    assert main(["mesh", str(d / "slice.npy"), "-o", str(d / "m.stl"), "--sites", "150"]) == 0
    out = capsys.readouterr().out
    assert (d / "m_material0.stl").exists() and (d / "m_material1.stl").exists()
    notes = [line for line in out.splitlines() if line.startswith("note:")]
    assert notes == [f"note: {d / 'm_material2.stl'} is from an earlier run, not this one"]
    assert (d / "m_material2.stl").read_text() == "old"
    assert main(["mesh", str(d / "slice.npy"), "-o", str(d / "n.stl"), "--sites", "150"]) == 0
    assert "note:" not in capsys.readouterr().out


def test_ctrl_c_while_a_checkpoint_slice_is_written(tmp_path, monkeypatch):
    """A Ctrl-C inside numpy's zip writer surfaces as zipfile's ValueError ("Can't close the
    ZIP file while there is an open writing handle"): the save raises KeyboardInterrupt (the
    CLI's exit 130), leaves no half-written file, and a later run resumes past a stray one."""
    import ctseg.checkpoint as checkpoint
    from ctseg.params import resolve

    vol = make_volume(2, 24, seed=1).image
    seg = ctseg.segment_image(vol[0], n_sites=30)
    ck = checkpoint.Checkpoint(tmp_path / "ck", vol, resolve(None))
    assert ck.load() == {}
    ck.save(0, seg)

    def interrupted(path, seg):
        with open(path, "wb") as fh:
            fh.write(b"PK half")
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt:
            raise ValueError("Can't close the ZIP file while there is an open writing handle") from None

    monkeypatch.setattr(checkpoint, "_save_slice", interrupted)
    with pytest.raises(KeyboardInterrupt):
        ck.save(1, seg)
    assert sorted(os.listdir(tmp_path / "ck")) == ["meta.json", "slice_00000.npz"]
    (tmp_path / "ck" / "slice_00001.npz.tmp.npz").write_bytes(b"PK half")  # killed harder
    assert list(checkpoint.Checkpoint(tmp_path / "ck", vol, resolve(None)).load()) == [0]
    assert "1 finished slice(s)" in checkpoint.resume_hint(tmp_path / "ck")
