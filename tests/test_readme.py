"""The README's install and run instructions are the ones the tests and CI run, word for
word (a test that installs more than the README says would hide a broken README)."""
import os
import re

import numpy as np

from conftest import requires_rendering

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def _read(*parts):
    with open(os.path.join(ROOT, *parts)) as fh:
        return fh.read()


def _pip_lines(script):
    return [line.strip() for line in script.splitlines()
            if re.search(r"\bpip\b.*\binstall\b", line) and not line.strip().startswith("#")]


def test_ci_runs_the_readme_test_command():
    readme = _read("README.md")
    block = readme.split("Run the test suite", 1)[1].split("```sh", 1)[1].split("```", 1)[0].strip()
    assert block in _read(".ci", "run").splitlines()


def test_paraview_install_is_the_readme_script():
    readme = _read("README.md")
    assert "`plugin/paraview/install.sh ~/ctseg-pv`" in readme
    runner = _read("plugin", "paraview", "run_tests.sh")
    assert 'plugin/paraview/install.sh "$env"' in runner
    assert _pip_lines(runner) == []  # nothing installed beside the script
    install = _read("plugin", "paraview", "install.sh")
    assert "pyproject.toml" in install  # its dependency list is the package's own


def test_slicer_install_is_the_readme_line():
    readme = _read("README.md")
    assert 'slicer.util.pip_install("/path/to/ctseg")' in readme
    pips = _pip_lines(_read("plugin", "slicer", "run_tests.sh"))
    # the test host (slicer-core, pytest), then ctseg as pip_install does: the package alone
    ctseg_lines = [p for p in pips if "slicer-core" not in p]
    assert ctseg_lines and all(p.endswith(" .") for p in ctseg_lines), ctseg_lines


def _first_command():
    readme = _read("README.md")
    block = readme.split("Run the main job on the sample data", 1)[1].split("```sh", 1)[1]
    return block.split("```", 1)[0].strip()


@requires_rendering
def test_first_command_meshes_the_sample_volume(tmp_path, monkeypatch, capsys):
    """The README's main job, as written after its install step, on the shipped sample
    volume: every output written, every material found, Dice near what the README says."""
    import json
    import shlex

    from ctseg.cli import main

    command = _first_command()
    assert command.startswith("python3 -m venv .venv && . .venv/bin/activate && pip install . &&")
    job = shlex.split(command.rsplit("&&", 1)[1])
    assert job[:2] == ["ctseg", "mesh"] and "--mode" in job and job[job.index("--mode") + 1] == "3d"
    monkeypatch.chdir(tmp_path)
    os.symlink(os.path.join(ROOT, "sample_data"), "sample_data")
    os.mkdir("out")
    assert main(job[1:]) == 0
    report = json.loads((tmp_path / job[job.index("--report") + 1]).read_text())
    for flag in ("-o", "--surfaces", "--report", "--figure"):
        assert (tmp_path / job[job.index(flag) + 1]).is_file(), flag
    assert report["n_materials"] == 4
    # measured 0.982 / 0.739 / 0.982 / 0.940 (the README's numbers; 0.742 polymer before
    # Qhull's new tetrahedron order, 0.716 before the raised density, 0.699 before the
    # transition votes)
    assert np.all(np.array(report["accuracy"]["dice"]) >= [0.97, 0.60, 0.95, 0.91])
    assert "Dice per material" in capsys.readouterr().out


def _code_block(words):
    """The README's ```python block that holds ``words``."""
    blocks = re.findall(r"```python\n(.*?)```", _read("README.md"), re.S)
    found = [b for b in blocks if words in b]
    assert len(found) == 1, words
    return found[0]


def test_python_example_runs(monkeypatch):
    """The README's Python example, as written, on the sample slice and volume."""
    monkeypatch.chdir(ROOT)
    scope = {}
    exec(_code_block("ctseg.segment_volume(volume"), scope)
    assert scope["tseg"].tetrahedra.shape[1] == 4 and len(scope["tseg"].surfaces) == 4
    assert len(scope["vseg"].slices) == 40 and scope["seg"].diagnostics["parameters"]


def test_vtk_example_runs(tmp_path, monkeypatch):
    """The README's VTK example, as written, on a small NIfTI volume: tetrahedra under Mode
    'auto', then triangles with a slice index under Mode 'slices'."""
    from vtkmodules.vtkIOImage import vtkNIFTIImageWriter
    from vtkmodules.vtkIOXML import vtkXMLPolyDataReader, vtkXMLUnstructuredGridReader

    from ctseg.filters.convert import array_to_image
    from ctseg.phantoms import make_volume

    monkeypatch.chdir(tmp_path)
    writer = vtkNIFTIImageWriter()
    writer.SetInputData(array_to_image(make_volume(6, 32, seed=1).image.astype(np.float32)))
    writer.SetFileName("part.nii.gz")
    writer.Write()
    exec(_code_block("CTSegmentFilter"), {})
    tets = vtkXMLUnstructuredGridReader()
    tets.SetFileName("part_tetra.vtu")
    tets.Update()
    grid = tets.GetOutput()
    assert grid.GetNumberOfCells() > 0 and grid.GetCellType(0) == 10  # VTK_TETRA
    tris = vtkXMLPolyDataReader()
    tris.SetFileName("part_slices.vtp")
    tris.Update()
    poly = tris.GetOutput()
    assert poly.GetNumberOfPolys() > 0 and poly.GetCellData().GetArray("slice").GetRange()[1] == 5
