"""The bad-input matrix, end to end through ``ctseg mesh``: every case either fails with
exit status 2 and one line naming the problem (and leaves no output file), or gives the
documented valid result. Function-level checks of the same rules live beside each stage
(test_pipeline.py, test_io.py); here is what a user at the command line sees."""
import os

import numpy as np
import pytest

from ctseg.cli import main
from ctseg.filters import array_to_image
from ctseg.geometry import ImageGeometry

from file_writers import write_ct_dicom


def _disc(size=24, dtype=np.float64):
    yy, xx = np.mgrid[0:size, 0:size]
    img = 20.0 + 180.0 * ((xx - size / 2) ** 2 + (yy - size / 2) ** 2 < (size / 3) ** 2)
    return img.astype(dtype)


def _vtk_write(writer_cls, path, data, **extra):
    w = writer_cls()
    w.SetFileName(str(path))
    w.SetInputData(data)
    for name, value in extra.items():
        getattr(w, name)(value)
    w.Write()


def write_format(path, arr):
    """Write ``arr`` in the format its extension names (a valid file)."""
    path = str(path)
    ext = ".nii.gz" if path.endswith(".nii.gz") else os.path.splitext(path)[1]
    if ext == ".npy":
        np.save(path, arr)
    elif ext == ".png":
        from vtkmodules.vtkIOImage import vtkPNGWriter

        _vtk_write(vtkPNGWriter, path, array_to_image(arr.astype(np.uint8)))
    elif ext == ".tif":
        import tifffile

        tifffile.imwrite(path, arr.astype(np.uint16))
    elif ext == ".dcm":
        write_ct_dicom(path, arr.astype(np.uint16))
    elif ext == ".nrrd":
        import nrrd

        nrrd.write(path, arr, index_order="C")
    elif ext == ".nii.gz":
        from vtkmodules.vtkIOImage import vtkNIFTIImageWriter

        _vtk_write(vtkNIFTIImageWriter, path, array_to_image(arr))
    elif ext == ".mha":
        from vtkmodules.vtkIOImage import vtkMetaImageWriter

        _vtk_write(vtkMetaImageWriter, path, array_to_image(arr))
    elif ext == ".vti":
        from vtkmodules.vtkIOXML import vtkXMLImageDataWriter

        _vtk_write(vtkXMLImageDataWriter, path, array_to_image(arr, ImageGeometry()))
    else:
        raise ValueError(ext)


def run(tmp_path, capsys, args):
    rc = main(["mesh"] + [str(a) for a in args])
    return rc, capsys.readouterr().err.strip()


def assert_refused(tmp_path, capsys, args, *words):
    before = set(os.listdir(tmp_path))
    rc, err = run(tmp_path, capsys, args)
    assert rc == 2, err
    assert err.startswith("ctseg: error:") and len(err.splitlines()) == 1, err
    assert "Traceback" not in err
    for word in words:
        assert word in err, (word, err)
    assert set(os.listdir(tmp_path)) == before, "an output was written"


# ---------------------------------------------------------------- arrays that are refused
@pytest.mark.parametrize("name,array,words", [
    ("1d", np.zeros(10), ["neither a slice nor a volume"]),
    ("4d", np.zeros((2, 3, 4, 5)), ["neither a slice nor a volume"]),
    ("empty", np.zeros((0, 5)), ["empty"]),
    ("one_pixel", np.ones((1, 1)), ["too small"]),
    ("one_row", np.ones((1, 30)), ["too small"]),
    ("nan", np.where(np.eye(8) > 0, np.nan, 1.0), ["NaN or infinite", "row 0, col 0"]),
    ("inf", np.where(np.eye(8) > 0, np.inf, 1.0), ["NaN or infinite"]),
    ("complex", np.ones((8, 8), complex), ["complex"]),
    ("strings", np.array([["a", "b"], ["c", "d"]]), ["numeric"]),
    ("rgb_npy", np.zeros((40, 50, 3)), ["colour", "gray"]),
    ("subnormal", _disc(16) * 1e-310, ["out of the range", "rescale"]),
    ("huge", _disc(16) * 1e300, ["out of the range", "rescale"]),
    ("subnormal_volume", np.stack([_disc(16)] * 3) * 1e-310, ["out of the range", "rescale"]),
])
def test_refused_arrays(tmp_path, capsys, name, array, words):
    np.save(tmp_path / "in.npy", array)
    assert_refused(tmp_path, capsys, [tmp_path / "in.npy", "-o", tmp_path / "m.vtp", "--jobs", "1"],
                   "in.npy" if name not in ("nan", "inf") else "", *words)


# ------------------------------------------------------------- arrays with a valid result
@pytest.mark.parametrize("name,array,n_materials", [
    ("two_by_two", np.array([[0.0, 0.0], [0.0, 10.0]]), None),
    ("constant", np.full((20, 20), 7.0), 1),
    ("bool", _disc(24) > 100, 2),
    ("int8", (_disc(24) / 2 - 60).astype(np.int8), 2),
    ("uint16", (_disc(24) * 300).astype(np.uint16), 2),
    ("int64", (_disc(24) * 1e6).astype(np.int64), 2),
    ("float32_1e30", (_disc(24) * 1e28).astype(np.float64), 2),
    ("rgb_png", None, 2),
])
def test_valid_results(tmp_path, capsys, name, array, n_materials):
    import json

    if name == "rgb_png":  # colour pictures are converted to luminance, not refused
        from vtkmodules.vtkIOImage import vtkPNGWriter

        rgb = np.zeros((24, 24, 3), np.uint8)
        rgb[_disc(24) > 100] = (200, 60, 10)
        img = array_to_image(rgb, components=3)
        _vtk_write(vtkPNGWriter, tmp_path / "in.png", img)
        src = tmp_path / "in.png"
    else:
        np.save(tmp_path / "in.npy", array)
        src = tmp_path / "in.npy"
    rc, err = run(tmp_path, capsys, [src, "-o", tmp_path / "m.vtp", "--report", tmp_path / "r.json", "-q"])
    assert rc == 0, err
    report = json.loads((tmp_path / "r.json").read_text())
    assert report["mesh_checks"]["ok"]
    if n_materials is not None:
        assert report["n_materials"] == n_materials


# ---------------------------------------------------------------------- bad parameters
@pytest.mark.parametrize("extra,words", [
    (["--sites", "-5"], ["n_sites"]),
    (["--sites", "3"], ["n_sites", "[4,"]),
    (["--sites", "many"], ["n_sites", "not a number"]),
    (["--sites", "100000"], ["n_sites", "at most 576"]),
    (["--materials", "-1"], ["n_materials"]),
    (["--set", "lamb=3"], ["lamb", "did you mean 'lam'"]),
    (["--set", "lam"], ["NAME=VALUE"]),
    (["--set", "init=grid"], ["init", "'ward'"]),
    (["--materials", "9"], ["n_materials", "9 materials"]),
    (["--seed", "-1"], ["seed"]),
    (["--jobs", "-2"], ["n_jobs"]),
    (["--sites", "inf"], ["n_sites"]), (["--sites", "nan"], ["n_sites"]),
    (["--seed", "inf"], ["seed"]), (["--set", "max_iter=1e400"], ["max_iter"]),
    (["--set", "merge_floor_255=0"], ["merge_floor_255"]),
])
def test_bad_parameters(tmp_path, capsys, extra, words):
    arr = _disc(24)
    np.save(tmp_path / "in.npy", np.stack([arr, arr]) if "--jobs" in extra else arr)
    assert_refused(tmp_path, capsys, [tmp_path / "in.npy", "-o", tmp_path / "m.vtp"] + extra, *words)


def test_out_of_range_energy_parameters_through_the_api():
    """lambda, beta, theta and thresholds are Python/VTK/plugin parameters, not CLI flags."""
    import ctseg
    from ctseg.errors import ParameterError

    for kw, word in [({"lam": -1.0}, "lam"), ({"beta": -0.1}, "beta"), ({"theta_255": -3.0}, "theta_255"),
                     ({"theta": -3.0}, "theta_255"),
                     ({"step_threshold": -1.0}, "step_threshold"), ({"merge_k": -1.0}, "merge_k"),
                     ({"merge_threshold": 0.0}, "merge_threshold"), ({"tol_px": 0.0}, "tol_px"),
                     ({"lamda": 1.0}, "did you mean 'lam'"),
                     ({"init": "grid"}, "init")]:
        with pytest.raises(ParameterError, match=word):
            ctseg.segment_image(_disc(24), n_sites=30, **kw)


# ----------------------------------------------------------------------- bad geometry
@pytest.mark.parametrize("spacing,word", [("-1 1", "spacing"), ("0 1", "spacing")])
def test_negative_or_zero_spacing(tmp_path, capsys, spacing, word):
    body = _disc(16).astype("<f8").tobytes()
    head = (f"NRRD0004\ntype: double\ndimension: 2\nsizes: 16 16\nspacings: {spacing}\n"
            "endian: little\nencoding: raw\n\n").encode()
    (tmp_path / "in.nrrd").write_bytes(head + body)
    assert_refused(tmp_path, capsys, [tmp_path / "in.nrrd", "-o", tmp_path / "m.vtp"], word, "> 0")


# ----------------------------------------------------------- truncated and corrupt files
FORMATS = [".npy", ".png", ".tif", ".dcm", ".nrrd", ".nii.gz", ".mha", ".vti"]


@pytest.mark.parametrize("ext", FORMATS)
def test_truncated_files(tmp_path, capsys, ext):
    write_format(tmp_path / f"ok{ext}", _disc(32))
    data = (tmp_path / f"ok{ext}").read_bytes()
    (tmp_path / f"cut{ext}").write_bytes(data[: len(data) // 2])
    os.unlink(tmp_path / f"ok{ext}")
    assert_refused(tmp_path, capsys, [tmp_path / f"cut{ext}", "-o", tmp_path / "m.vtp"], f"cut{ext}")


@pytest.mark.parametrize("ext", FORMATS)
def test_garbage_files(tmp_path, capsys, ext):
    (tmp_path / f"junk{ext}").write_bytes(bytes(range(256)) * 4)
    assert_refused(tmp_path, capsys, [tmp_path / f"junk{ext}", "-o", tmp_path / "m.vtp"], f"junk{ext}")


def test_wrong_extension(tmp_path, capsys):
    write_format(tmp_path / "real.nrrd", _disc(16))
    os.rename(tmp_path / "real.nrrd", tmp_path / "named.mha")
    assert_refused(tmp_path, capsys, [tmp_path / "named.mha", "-o", tmp_path / "m.vtp"], "named.mha")


def test_missing_file_and_empty_folder(tmp_path, capsys):
    assert_refused(tmp_path, capsys, [tmp_path / "nope.npy", "-o", tmp_path / "m.vtp"], "no such file")
    (tmp_path / "empty").mkdir()
    assert_refused(tmp_path, capsys, [tmp_path / "empty", "-o", tmp_path / "m.vtp"], "no DICOM or TIFF")


def test_folder_with_mixed_dicom_series(tmp_path, capsys):
    d = tmp_path / "dicom"
    d.mkdir()
    for k in range(2):
        write_ct_dicom(d / f"a{k}.dcm", np.zeros((8, 8), np.uint16), instance=k + 1,
                       position=(0, 0, k), series_uid="1.2.3.1")
        write_ct_dicom(d / f"b{k}.dcm", np.ones((8, 8), np.uint16), instance=k + 5,
                       position=(0, 0, k), series_uid="1.2.3.2")
    assert_refused(tmp_path, capsys, [d, "-o", tmp_path / "m.vtp"], "2 DICOM series", "--series")


@pytest.mark.parametrize("orientation,words", [((1, 0, 0), ["ImageOrientationPatient", "6 numbers"]),
                                               ((1, 0, 0, 1, 0, 0), ["parallel"])])
def test_bad_dicom_orientation(tmp_path, capsys, orientation, words):
    write_ct_dicom(tmp_path / "s.dcm", np.zeros((8, 8), np.uint16), orientation=orientation)
    assert_refused(tmp_path, capsys, [tmp_path / "s.dcm", "-o", tmp_path / "m.vtp"], *words)


@pytest.mark.parametrize("truth,word", [(np.full((16, 16), 0.5), "whole numbers"),
                                         (np.full((16, 16), -1), "whole numbers"),
                                         (np.full((16, 16), np.nan), "whole numbers"),
                                         (np.full((16, 16), 10 ** 6), "whole numbers"),
                                         (np.zeros((8, 8)), "truth shape")])
def test_bad_truth_labels(tmp_path, capsys, truth, word):
    np.save(tmp_path / "in.npy", _disc(16))
    np.save(tmp_path / "t.npy", truth)
    assert_refused(tmp_path, capsys, [tmp_path / "in.npy", "-o", tmp_path / "m.vtp", "--truth",
                                      tmp_path / "t.npy"], "t.npy", word)


def test_series_of_a_file_that_has_none(tmp_path, capsys):
    np.save(tmp_path / "in.npy", _disc(16))
    assert_refused(tmp_path, capsys, [tmp_path / "in.npy", "-o", tmp_path / "m.vtp", "--series", "1.2.3"],
                   "only DICOM data have series")


def test_malformed_dask_address(tmp_path, capsys):
    arr = _disc(16)
    np.save(tmp_path / "vol.npy", np.stack([arr, arr]))
    assert_refused(tmp_path, capsys, [tmp_path / "vol.npy", "-o", tmp_path / "m.vtp", "--mode", "slices",
                                      "--dask", "notanaddress"], "Dask scheduler", "notanaddress")


def test_params_file_that_is_not_an_object(tmp_path, capsys):
    np.save(tmp_path / "in.npy", _disc(16))
    (tmp_path / "p.json").write_text("[1, 2]")
    assert_refused(tmp_path, capsys, [tmp_path / "in.npy", "-o", tmp_path / "m.vtp", "--params",
                                      tmp_path / "p.json"], "--params", "JSON object")


# ------------------------------------------------------------------------ bad outputs
@pytest.mark.parametrize("output,words", [
    ("m.xyz", ["unknown output format"]),
    ("nowhere/m.vtp", ["does not exist"]),
    (".", ["is a folder"]),
    ("/proc/m.vtp", ["/proc"]),
])
def test_bad_outputs(tmp_path, capsys, monkeypatch, output, words):
    monkeypatch.chdir(tmp_path)
    np.save(tmp_path / "in.npy", _disc(16))
    assert_refused(tmp_path, capsys, [tmp_path / "in.npy", "-o", output], *words)


@pytest.mark.parametrize("flag,name", [("--figure", "f.jpg"), ("--boundary", "b.ply"),
                                       ("--report", "r.txt")])
def test_bad_side_outputs(tmp_path, capsys, flag, name):
    np.save(tmp_path / "in.npy", _disc(16))
    assert_refused(tmp_path, capsys, [tmp_path / "in.npy", "-o", tmp_path / "m.vtp", flag,
                                      tmp_path / name], "unknown output format", name)


def test_one_file_for_two_outputs(tmp_path, capsys):
    np.save(tmp_path / "in.npy", _disc(16))
    assert_refused(tmp_path, capsys, [tmp_path / "in.npy", "-o", tmp_path / "m.vtp", "--boundary",
                                      tmp_path / "m.vtp"], "--boundary", "the same file as -o")


@pytest.mark.parametrize("name", ["p{v2}.stl", "p{0}.mlp", "a}b.stl"])
def test_braces_in_a_pattern_output_name(tmp_path, capsys, name):
    """STL and MLP outputs write one file per material named after the output: braces in
    that name are plain characters."""
    np.save(tmp_path / "in.npy", _disc(24))
    rc, err = run(tmp_path, capsys, [tmp_path / "in.npy", "-o", tmp_path / name, "-q"])
    assert rc == 0, err
    stem = name[:-4]
    assert (tmp_path / f"{stem}_material1.{'stl' if name.endswith('stl') else 'ply'}").exists()


@pytest.mark.parametrize("output,blocker", [("y.obj", "y.mtl"), ("z.stl", "z_material1.stl")])
def test_side_file_blocked_by_a_folder(tmp_path, capsys, output, blocker):
    """A file written beside the output (OBJ's .mtl, STL's one file per material) that
    cannot be written leaves no output at all, and says which."""
    np.save(tmp_path / "in.npy", _disc(24))
    (tmp_path / blocker).mkdir()
    rc, err = run(tmp_path, capsys, [tmp_path / "in.npy", "-o", tmp_path / output, "-q"])
    assert rc == 2 and "Traceback" not in err and blocker in err and "is a folder" in err, err
    assert sorted(os.listdir(tmp_path)) == sorted(["in.npy", blocker]), os.listdir(tmp_path)


def test_too_large_for_memory_fails_before_the_work(tmp_path, capsys, monkeypatch):
    """What cannot fit is refused at once, saying how much it needs and what is there."""
    import ctseg.resources

    arr = _disc(64)
    np.save(tmp_path / "in.npy", arr)
    np.save(tmp_path / "vol.npy", np.stack([arr] * 4))
    monkeypatch.setattr(ctseg.resources, "available_bytes", lambda: 2 ** 16)  # 64 KiB free
    assert_refused(tmp_path, capsys, [tmp_path / "in.npy", "-o", tmp_path / "m.vtp"],
                   "64 x 64 slice needs about", "GiB of memory", "crop or downsample")
    assert_refused(tmp_path, capsys, [tmp_path / "vol.npy", "-o", tmp_path / "m.vtp", "--jobs", "2"],
                   "4 x 64 x 64 volume with 2 process(es)", "fewer worker processes")
    monkeypatch.setattr(ctseg.resources, "available_bytes", lambda: None)  # unknown: no check
    rc, err = run(tmp_path, capsys, [tmp_path / "in.npy", "-o", tmp_path / "m.vtp", "-q"])
    assert rc == 0, err
