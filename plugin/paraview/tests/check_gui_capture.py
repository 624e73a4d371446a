"""Check what the GUI test left: the checks its startup script ran inside ParaView's GUI
(a JSON file) and the capture of the whole screen (a PNG), in which the GUI must show the
segmented part in CT Segment's material colours. Run with pvpython (for VTK's PNG reader).

    pvpython check_gui_capture.py RESULT.json CAPTURE.png

Prints 'N passed, M failed' and exits non-zero on any failure or a missing file.
"""
import json
import os
import sys

import numpy as np
from vtkmodules.util import numpy_support
from vtkmodules.vtkIOImage import vtkPNGReader

# the material colours the GUI script sets (0-255), and how many screen pixels of each
# hue the render view must show at least (the scalar bar alone has about 1,500 of each)
COLOURS = {"polymer": (230, 158, 0), "aluminium": (87, 181, 232), "steel": (0, 158, 115)}
MIN_PIXELS = 4000
results = []
result_path, capture = sys.argv[1], sys.argv[2]
if not os.path.exists(result_path):
    results.append(("the GUI's startup script wrote its result", f"no {result_path}: the "
                    "GUI did not start, did not load the plugin or the script failed"))
else:
    with open(result_path) as fh:
        result = json.load(fh)
    results += [(f"GUI: {name}", err) for name, err in result["checks"]]
    print("    in the GUI:", {k: v for k, v in result.items() if k != "checks"})
if not os.path.exists(capture) or os.path.getsize(capture) < 10000:
    results.append(("the capture of the GUI's window", f"no (or an empty) {capture}"))
else:
    reader = vtkPNGReader()
    reader.SetFileName(capture)
    reader.Update()
    img = reader.GetOutput()
    nx, ny, _ = img.GetDimensions()
    rgb = numpy_support.vtk_to_numpy(img.GetPointData().GetScalars())[:, :3].astype(float)
    unit = rgb / np.maximum(np.linalg.norm(rgb, axis=1, keepdims=True), 1e-9)
    bright = rgb.max(axis=1) > 60
    counts = {}
    for name, ref in COLOURS.items():
        ref = np.asarray(ref, float) / np.linalg.norm(ref)
        counts[name] = int(((unit @ ref > 0.995) & bright).sum())  # that hue, shaded or not
    print(f"    capture {nx} x {ny}: pixels of each material's hue {counts}")
    err = None if min(counts.values()) >= MIN_PIXELS else f"too few pixels of a material: {counts}"
    results.append(("the captured GUI shows the segmented part in the material colours", err))
for name, err in results:
    print(f"PASS {name}" if err is None else f"FAIL {name}\n{err}")
failed = sum(1 for _, err in results if err)
print(f"{len(results) - failed} passed, {failed} failed")
sys.stdout.flush()
os._exit(1 if failed else 0)
