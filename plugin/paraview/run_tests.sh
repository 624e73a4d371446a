#!/usr/bin/env bash
# Test the ParaView plugin in Debian's ParaView (5.11, VTK 9.2, Python 3.11), headless.
# Installs ParaView with apt if pvpython is missing (root needed), installs ctseg with the
# README's script (plugin/paraview/install.sh), then runs test_paraview.py under Xvfb. Usage: plugin/paraview/run_tests.sh [SCREENSHOT.png]
set -euo pipefail
cd "$(dirname "$0")/../.."
if ! command -v pvpython >/dev/null || ! command -v xvfb-run >/dev/null; then
    apt-get update -qq
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends \
        paraview python3-paraview xvfb >/dev/null
fi
env=.venv-paraview
# the README's install step, word for word
plugin/paraview/install.sh "$env"
site=$("$env/bin/python" -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')
shot=${1:-$(mktemp -d)/paraview.png}
PYTHONPATH="$PWD/plugin/paraview/compat:$site" xvfb-run -a pvpython plugin/paraview/test_paraview.py "$shot"
