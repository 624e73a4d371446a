"""What the pvpython suites share: checks that record a pass or the traceback (ParaView
prints and swallows exceptions raised inside RequestData, so every check is on fetched
data), a .vti written and opened by ParaView's reader, a fetched non-empty output, and
the closing 'N passed, M failed' line with the exit status."""
import os
import sys
import time
import traceback

from paraview import servermanager
from paraview.simple import XMLImageDataReader

from ctseg.filters import array_to_image

RESULTS = []


def check(name):
    """Decorator: run the function now, record and print PASS (with its time) or FAIL
    with the traceback."""
    def run(fn):
        t0 = time.perf_counter()
        try:
            fn()
            RESULTS.append((name, None))
            print(f"PASS {name} ({time.perf_counter() - t0:.1f} s)")
        except Exception:
            RESULTS.append((name, traceback.format_exc()))
            print(f"FAIL {name}\n{traceback.format_exc()}")
        sys.stdout.flush()
        return fn
    return run


def write_vti(path, arr, geom):
    """Write ``arr`` with ``geom`` as VTK XML image data; return ParaView's reader of it."""
    from vtkmodules.vtkIOXML import vtkXMLImageDataWriter

    w = vtkXMLImageDataWriter()
    w.SetFileName(path)
    w.SetInputData(array_to_image(arr, geom))
    w.Write()
    return XMLImageDataReader(FileName=[path])


def fetch(proxy, port=0):
    """The proxy's output on ``port``, which must hold cells (an error in RequestData
    leaves it empty)."""
    data = servermanager.Fetch(proxy, idx=port)
    assert data is not None and data.GetNumberOfCells() > 0, "empty output (error in RequestData?)"
    return data


def finish():
    """Print the summary line and exit: 1 if any check failed."""
    failed = sum(1 for _, err in RESULTS if err)
    print(f"{len(RESULTS) - failed} passed, {failed} failed")
    sys.stdout.flush()
    # skip ParaView's teardown: under Xvfb it ends in a GLXBadContext error that turns a
    # passing run's exit status into 1
    os._exit(1 if failed else 0)
