#!/usr/bin/env bash
# The plugin in ParaView's GUI: starts the `paraview` binary on $DISPLAY (run_tests.sh's
# Xvfb; without a DISPLAY this script reruns itself under xvfb-run) with the README's
# PYTHONPATH and PV_PLUGIN_PATH and the startup script test_paraview_gui.py, waits for the
# script's result file, captures the whole screen with ImageMagick's `import`, closes
# ParaView and checks both with check_gui_capture.py. A hung GUI is killed after 300 s.
# Usage: plugin/paraview/tests/run_gui_test.sh PYTHONPATH CAPTURE.png
set -euo pipefail
if [ -z "${DISPLAY:-}" ]; then
    exec xvfb-run -a -s "-screen 0 1600x1000x24 -noreset" "$0" "$@"
fi
cd "$(dirname "$0")/../../.."
pythonpath=$1
capture=$2
work=$(mktemp -d)
result="$work/result.json"
rm -f "$capture"
# -geometry (Qt's option): the window fills the 1600 x 1000 screen (there is no window manager)
CTSEG_GUI_RESULT="$result" PYTHONPATH="$pythonpath" PV_PLUGIN_PATH="$PWD/plugin/paraview" \
    timeout -k 10 300 paraview -geometry 1600x1000+0+0 --dr \
    --script=plugin/paraview/tests/test_paraview_gui.py >"$work/paraview.log" 2>&1 &
pid=$!
for _ in $(seq 280); do
    if [ -s "$result" ] || ! kill -0 "$pid" 2>/dev/null; then break; fi
    sleep 1
done
if kill -0 "$pid" 2>/dev/null; then
    sleep 4  # the GUI paints its panels once the script has returned
    import -window root "$capture" || echo "import: could not capture the screen"
    kill "$pid" 2>/dev/null || true
fi
wait "$pid" 2>/dev/null || echo "ParaView's exit status: $? (124: killed after 300 s; 143: closed by this script)"
if [ ! -s "$result" ]; then
    echo "ParaView's log:"
    tail -n 40 "$work/paraview.log" || true
fi
PYTHONPATH="$pythonpath" pvpython plugin/paraview/tests/check_gui_capture.py "$result" "$capture"
