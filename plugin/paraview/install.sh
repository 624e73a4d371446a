#!/usr/bin/env bash
# Install ctseg for a ParaView whose Python is the system's (Debian/Ubuntu: apt install
# paraview python3-paraview): a virtual environment that sees ParaView's Python, holding
# ctseg and the dependencies of pyproject.toml that ParaView lacks. numpy and scipy stay
# the system's (a newer numpy would shadow the one the system's scipy was built for) and
# VTK stays ParaView's own. Prints, last, the command that starts ParaView with it.
# Usage: plugin/paraview/install.sh [VENV]    (default: ~/ctseg-pv)
set -euo pipefail
src="$(cd "$(dirname "$0")/../.." && pwd)"
env=${1:-$HOME/ctseg-pv}
if [ ! -x "$env/bin/python" ]; then
    /usr/bin/python3 -m venv --system-site-packages "$env"
fi
numpy_version=$(/usr/bin/python3 -c 'import numpy; print(numpy.__version__)')
# the dependencies from pyproject.toml (one source), less what ParaView and the system bring
deps=$(/usr/bin/python3 - "$src/pyproject.toml" <<'PY'
import re, sys, tomllib
with open(sys.argv[1], "rb") as fh:
    deps = tomllib.load(fh)["project"]["dependencies"]
print(" ".join(d for d in deps if re.split(r"[<>=!~ ;\[]", d)[0].lower() not in ("vtk", "numpy", "scipy")))
PY
)
# shellcheck disable=SC2086  # one word per requirement
"$env/bin/pip" install -q "numpy==$numpy_version" $deps
"$env/bin/pip" install -q --no-deps --force-reinstall "$src"
site=$("$env/bin/python" -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')
echo "PYTHONPATH=$src/plugin/paraview/compat:$site paraview"
