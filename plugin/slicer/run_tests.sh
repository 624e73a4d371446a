#!/usr/bin/env bash
# Test the 3D Slicer module's Logic on PyPI's slicer-core (MRML, storage nodes and
# segmentations without the GUI). slicer-core pins its own VTK, so it gets a virtual
# environment of its own, with ctseg installed into it.
# Usage: plugin/slicer/run_tests.sh
set -euo pipefail
cd "$(dirname "$0")/../.."
env=.venv-slicer
if [ ! -x "$env/bin/python" ]; then
    python3 -m venv "$env"
fi
"$env/bin/pip" install -q slicer-core pytest
"$env/bin/pip" install -q --force-reinstall --no-deps . && "$env/bin/pip" install -q .
"$env/bin/python" -P -m pytest -p no:cacheprovider plugin/slicer/test_slicer_logic.py
