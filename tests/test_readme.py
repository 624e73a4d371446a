"""The README's install and run instructions are the ones the tests and CI run, word for
word (a test that installs more than the README says would hide a broken README)."""
import os
import re

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
