"""Checkpoints of a volume run: every finished slice saved at once, so an interrupted or
failed run resumes where it stopped, and never mixes slices of two runs."""
import json
import os
import shutil

import numpy as np

from .errors import InputError, ResumeError
from .params import RUN_ONLY
from .pipeline import SegmentedMesh


def checkpoint_folder(output):
    """Where a volume run keeps its finished slices until its outputs are written."""
    return os.fspath(output) + ".ctseg-partial"


def resume_hint(folder):
    """What a failed or interrupted run tells the user of its checkpoint ``folder``: how
    many finished slices it keeps for ``--resume``. A folder with none is removed (the run
    stopped before a slice was done: nothing to resume, nothing left behind)."""
    if not folder or not os.path.isdir(folder):
        return ""
    n = sum(1 for f in os.listdir(folder) if _slice_index(f) is not None)
    if not n:
        shutil.rmtree(folder, ignore_errors=True)
        return ""
    return (f"; {n} finished slice(s) are kept in {folder}: run the same command with "
            "--resume to go on from there")


class Checkpoint:
    """Finished slices of one volume run, saved one file each in a folder.

    ``meta.json`` names what the slices were made from (the volume's shape, dtype and
    SHA-1, the axis, every parameter); a run with anything different refuses the folder
    rather than mixing slices of two runs. Each slice is written under a temporary name
    and renamed, so an interrupt never leaves half a slice.
    """

    def __init__(self, folder, vol, params):
        import hashlib

        self.folder = os.fspath(folder)
        result = {k: v for k, v in params.flat().items() if k not in RUN_ONLY}
        self.meta = {"shape": list(vol.shape), "dtype": str(vol.dtype), "axis": params.axis,
                     "sha1": hashlib.sha1(np.ascontiguousarray(vol).tobytes()).hexdigest(),
                     "params": result}

    def _meta_path(self):
        return os.path.join(self.folder, "meta.json")

    def load(self):
        """{slice index: SegmentedMesh} already done; creates the folder if new."""
        if not os.path.isdir(self.folder):
            try:
                os.makedirs(self.folder)
            except OSError as exc:
                raise InputError(f"{self.folder}: cannot make the checkpoint folder ({exc.strerror})") from None
        if os.path.exists(self._meta_path()):
            with open(self._meta_path()) as fh:
                old = json.load(fh)
            if old != self.meta:
                differs = sorted(k for k in set(old) | set(self.meta) if old.get(k) != self.meta.get(k))
                if "params" in differs:
                    differs.remove("params")
                    differs += sorted(k for k in set(old["params"]) | set(self.meta["params"])
                                      if old["params"].get(k) != self.meta["params"].get(k))
                raise ResumeError(f"{self.folder}: these slices were made from another input or "
                                 f"other parameters (differs in: {', '.join(differs)}); delete "
                                 "the folder or run without resuming")
        else:
            with open(self._meta_path(), "w") as fh:
                json.dump(self.meta, fh)
        done = {}
        for name in sorted(os.listdir(self.folder)):
            k = _slice_index(name)
            if k is not None:
                done[k] = _load_slice(os.path.join(self.folder, name))
        return done

    def save(self, k, seg):
        path = os.path.join(self.folder, f"slice_{k:05d}.npz")
        tmp = path + ".tmp.npz"
        try:
            _save_slice(tmp, seg)
        except BaseException as exc:
            if os.path.exists(tmp):
                os.remove(tmp)
            # Ctrl-C inside numpy's zip writer comes out as zipfile's ValueError about an
            # open handle, raised while the KeyboardInterrupt was handled: still a Ctrl-C
            if not isinstance(exc, KeyboardInterrupt) and isinstance(exc.__context__, KeyboardInterrupt):
                raise KeyboardInterrupt from None
            raise
        os.replace(tmp, path)


def _slice_index(name):
    """The slice index of a finished slice's file name (slice_NNNNN.npz), else None (a
    half-written .tmp.npz among them)."""
    stem = name[6:-4]
    return int(stem) if name.startswith("slice_") and name.endswith(".npz") and stem.isdigit() else None


_SLICE_ARRAYS = ("points", "triangles", "material", "gray", "boundary_edges",
                 "boundary_sides", "material_gray", "adjacency")


def _save_slice(path, seg):
    np.savez(path, shape=np.array(seg.shape), diagnostics=np.array(json.dumps(seg.diagnostics)),
             **{name: getattr(seg, name) for name in _SLICE_ARRAYS})


def _load_slice(path):
    try:
        with np.load(path, allow_pickle=False) as z:
            return SegmentedMesh(shape=tuple(int(v) for v in z["shape"]),
                                 diagnostics=json.loads(str(z["diagnostics"])),
                                 **{name: z[name] for name in _SLICE_ARRAYS})
    except Exception as exc:
        raise InputError(f"{path}: a damaged checkpoint slice ({exc}); delete it") from None
