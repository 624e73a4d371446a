"""3D volumes, slice by slice (SPEC 8): one gray map and one set of material levels for the
whole volume, slices segmented in this process, in local worker processes or on a Dask
cluster, with the same result whichever runs them."""
import os
import time
from dataclasses import dataclass, field

import numpy as np

from ._validate import as_image, check_number
from .errors import CTSegError, InputError, ParameterError, ResumeError
from .intensity import gray_scale
from .pipeline import SEGMENT_DEFAULTS, SegmentedMesh, material_levels, segment_image
from .resources import (LEVEL_BYTES_PER_VOXEL, RESULT_BYTES_PER_VOXEL, check_memory,
                        slice_bytes)

AXES = {"z": 0, "y": 1, "x": 2}
"""Slice axis name -> axis of the (nz, ny, nx) array (VTK's k, j, i)."""

LEVEL_SAMPLE_VOXELS = 1 << 25
"""At most this many voxels (evenly spaced whole slices) measure the gray map and levels."""


def slice_axis(axis):
    """Numpy axis (0, 1, 2) of a slice axis given as 'z'/'y'/'x' or 0/1/2 (numpy order)."""
    if isinstance(axis, str) and axis.lower() in AXES:
        return AXES[axis.lower()]
    if isinstance(axis, (int, np.integer)) and not isinstance(axis, bool) and 0 <= axis <= 2:
        return int(axis)
    raise ParameterError(f"axis: expected 'z', 'y' or 'x' (or 0, 1, 2), got {axis!r}")


def volume_slice(volume, axis, k):
    """Slice ``k`` along ``axis`` of an (nz, ny, nx) volume as a (rows, cols) image.

    Along z the slice is ``volume[k]`` (rows = y, cols = x); along y it is
    ``volume[:, k, :]`` (rows = z, cols = x); along x ``volume[:, :, k]`` (rows = z,
    cols = y). :func:`slice_to_volume_index` maps its pixel coordinates back.
    """
    return np.take(volume, k, axis=slice_axis(axis))


def slice_to_volume_index(points, axis, k):
    """Points (x=col, y=row) of slice ``k`` -> (i, j, k) index coordinates of the volume
    (VTK's order: i along x, j along y, k along z)."""
    pts = np.asarray(points, float).reshape(-1, 2)
    col, row, pos = pts[:, 0], pts[:, 1], np.full(len(pts), float(k))
    ax = slice_axis(axis)
    if ax == 0:
        return np.column_stack([col, row, pos])
    if ax == 1:
        return np.column_stack([col, pos, row])
    return np.column_stack([pos, col, row])


@dataclass
class VolumeSegmentation:
    """Outcome of :func:`segment_volume`.

    Attributes
    ----------
    slices : list of SegmentedMesh
        One per slice along ``axis``, in slice order; material k means the same material in
        every slice. The per-pixel maps (``density``, ``cvt_labels``, ``corrected_image``)
        are dropped to keep memory bounded.
    axis : int
        Numpy axis of the (nz, ny, nx) volume that was sliced.
    material_gray : (K,) ndarray
        Gray level of each material in the input's units.
    diagnostics : dict
        The gray map, levels, executor, per-stage times summed over slices, wall time.
    """

    slices: list
    axis: int
    material_gray: np.ndarray
    diagnostics: dict = field(default_factory=dict)

    @property
    def n_materials(self):
        return len(self.material_gray)


def _segment_slice(image, params, keep_maps=False):
    """Worker: one slice; the per-pixel maps (as large as the slice) dropped unless asked."""
    seg = segment_image(image, **params)
    if not keep_maps:
        seg.density = None
        seg.cvt_labels = None
        seg.corrected_image = None
    return seg


def _sample_slices(n_slices, slice_voxels):
    """Evenly spaced slice indices whose voxels stay within LEVEL_SAMPLE_VOXELS."""
    n_keep = max(1, min(n_slices, LEVEL_SAMPLE_VOXELS // max(slice_voxels, 1)))
    return np.unique(np.linspace(0, n_slices - 1, n_keep).round().astype(int))


def as_volume(volume, name="volume"):
    """Return ``volume`` as a 3D numeric array (a 2D one as one slice), or raise InputError
    saying what is wrong. NaN and infinite values are refused here, before any slice runs."""
    try:
        vol = np.asarray(volume)
    except Exception as exc:
        raise InputError(f"{name}: cannot be read as an array ({exc})") from None
    if vol.ndim == 2:
        vol = vol[None]
    if vol.ndim != 3:
        raise InputError(f"{name}: expected a 3D array (slices, rows, cols), got shape {vol.shape}")
    if vol.size == 0:
        raise InputError(f"{name}: the array is empty (shape {vol.shape})")
    if vol.dtype == object or not (np.issubdtype(vol.dtype, np.number) or vol.dtype == bool) \
            or np.iscomplexobj(vol):
        raise InputError(f"{name}: expected real numbers, got dtype {vol.dtype}")
    if np.issubdtype(vol.dtype, np.floating):
        bad = ~np.isfinite(vol)
        if bad.any():
            k, r, c = np.argwhere(bad)[0]
            raise InputError(f"{name}: {int(bad.sum())} voxel(s) are NaN or infinite (first in "
                             f"slice {k}, row {r}, col {c})")
    return vol


def _run_local(tasks, n_jobs, on_done):
    """Run ``{k: task}`` in worker processes; ``on_done(k, seg)`` as each finishes."""
    from concurrent.futures import ProcessPoolExecutor, as_completed
    import multiprocessing

    # fork where there is one: spawn and forkserver start sys.executable, which inside
    # ParaView or Slicer is the application itself, and re-run the caller's __main__
    method = "fork" if "fork" in multiprocessing.get_all_start_methods() else "spawn"
    pool = ProcessPoolExecutor(max_workers=n_jobs, mp_context=multiprocessing.get_context(method),
                               initializer=_ignore_sigint)
    futures = {pool.submit(_segment_slice, *task): k for k, task in tasks.items()}
    try:
        for fut in as_completed(futures):
            k = futures[fut]
            on_done(k, _slice_result(fut.result, k))
    except BaseException:
        # Ctrl-C or a failed slice: no new slices; the workers finish the one they hold
        pool.shutdown(wait=False, cancel_futures=True)
        raise
    pool.shutdown()


def _ignore_sigint():
    """Workers leave Ctrl-C to the parent, which stops the run and reports once (a
    terminal sends SIGINT to the whole process group)."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)


def _run_dask(tasks, client, on_done):
    """Run ``{k: task}`` on a Dask cluster; ``on_done(k, seg)`` as each finishes."""
    try:
        from distributed import Client, as_completed
    except ImportError:
        raise ParameterError("client: Dask is not installed; pip install 'ctseg[dask]' "
                             "(or distributed)") from None

    own = isinstance(client, str)
    if own:
        try:
            client = Client(client, timeout=30)
        except (OSError, TimeoutError) as exc:
            raise ParameterError(f"client: cannot reach the Dask scheduler at {client} ({exc})") from None
    try:
        keys = list(tasks)
        # slices go to the workers as data, not inside the task graph
        images = client.scatter([tasks[k][0] for k in keys])
        futures = client.map(_segment_slice, images, [tasks[k][1] for k in keys],
                             [tasks[k][2] for k in keys], pure=False)
        index = {f.key: k for k, f in zip(keys, futures)}
        try:
            for fut in as_completed(futures):
                k = index[fut.key]
                on_done(k, _slice_result(fut.result, k))
        except BaseException:
            client.cancel(futures)
            raise
    finally:
        if own:
            client.close()


class _Checkpoint:
    """Finished slices of one volume run, saved one file each in a folder.

    ``meta.json`` names what the slices were made from (the volume's shape, dtype and
    SHA-1, the axis, every parameter); a run with anything different refuses the folder
    rather than mixing slices of two runs. Each slice is written under a temporary name
    and renamed, so an interrupt never leaves half a slice.
    """

    def __init__(self, folder, vol, axis, params):
        import hashlib

        self.folder = os.fspath(folder)
        self.meta = {"shape": list(vol.shape), "dtype": str(vol.dtype), "axis": int(axis),
                     "sha1": hashlib.sha1(np.ascontiguousarray(vol).tobytes()).hexdigest(),
                     "params": {k: repr(v) for k, v in sorted(params.items())}}

    def _meta_path(self):
        return os.path.join(self.folder, "meta.json")

    def load(self):
        """{slice index: SegmentedMesh} already done; creates the folder if new."""
        import json

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
            if name.startswith("slice_") and name.endswith(".npz"):
                done[int(name[6:-4])] = _load_slice(os.path.join(self.folder, name))
        return done

    def save(self, k, seg):
        path = os.path.join(self.folder, f"slice_{k:05d}.npz")
        tmp = path + ".tmp.npz"
        _save_slice(tmp, seg)
        os.replace(tmp, path)


_SLICE_ARRAYS = ("points", "triangles", "material", "gray", "boundary_edges",
                 "boundary_sides", "material_gray", "adjacency")


def _save_slice(path, seg):
    import json

    np.savez(path, shape=np.array(seg.shape), diagnostics=np.array(json.dumps(seg.diagnostics)),
             **{name: getattr(seg, name) for name in _SLICE_ARRAYS})


def _load_slice(path):
    import json

    try:
        with np.load(path, allow_pickle=False) as z:
            return SegmentedMesh(shape=tuple(int(v) for v in z["shape"]),
                                 diagnostics=json.loads(str(z["diagnostics"])),
                                 **{name: z[name] for name in _SLICE_ARRAYS})
    except Exception as exc:
        raise InputError(f"{path}: a damaged checkpoint slice ({exc}); delete it") from None


def _slice_result(get, k):
    try:
        return get()
    except CTSegError as exc:
        raise type(exc)(f"slice {k}: {exc}") from exc


def segment_volume(volume, axis="z", n_sites=None, seed=0, *, n_jobs=1, client=None,
                   progress=None, keep_maps=(), checkpoint=None, **params):
    """Segment a 3D volume slice by slice into triangle meshes with one numbering of the
    materials for the whole volume.

    The gray map onto 0-255 (:func:`ctseg.intensity.gray_scale`) and the material levels
    (:func:`ctseg.pipeline.material_levels`) are measured once on the volume (on evenly
    spaced whole slices, at most 2^25 voxels), then every slice is segmented against them
    (:func:`ctseg.segment_image` with ``gray_scale`` and ``levels_255``): material k is the
    same material in every slice, whether or not a slice holds it. A volume of one slice is
    a 2D problem with the volume's numbering.

    Parameters
    ----------
    volume : (nz, ny, nx) array_like
        The CT volume (a (rows, cols) array is one slice).
    axis : {'z', 'y', 'x'} or {0, 1, 2}
        Slice axis (see :func:`volume_slice` for the orientation of each slice).
    n_sites : int, optional
        Sites per slice; default one per 128 pixels of a slice.
    seed : int
        Seed of every slice's random initialisation.
    n_jobs : int
        Local worker processes (1 = in this process, 0 = one per CPU core).
    client : distributed.Client or str, optional
        A Dask client, or a scheduler address to connect to for this call; slices then run
        on that cluster and ``n_jobs`` is ignored.
    progress : callable, optional
        ``progress(fraction_done, message)`` after each slice.
    keep_maps : iterable of int
        Slices whose density and CVT maps are kept (for a figure); the others drop them.
    checkpoint : str or path-like, optional
        A folder where every finished slice is saved at once; slices already there, from
        a run on the same volume with the same parameters, are loaded instead of being
        computed again (resume after an interrupt or a failure). A folder from another
        input or other parameters raises InputError saying what differs.
    **params
        Any keyword of :func:`ctseg.segment_image` (``n_materials``, ``lam``, ...).

    Returns
    -------
    VolumeSegmentation

    Raises
    ------
    InputError
        Not a 3D (or 2D) finite numeric array; a slice's error names the slice.
    ParameterError
        Unknown parameter, bad axis, n_jobs < 0.
    """
    vol = as_volume(volume)
    ax = slice_axis(axis)
    unknown = sorted(set(params) - set(SEGMENT_DEFAULTS))
    if unknown:
        raise ParameterError(f"segment_volume: unknown parameter(s) {', '.join(unknown)}; "
                             f"valid: {', '.join(sorted(SEGMENT_DEFAULTS))}")
    n_jobs = check_number(n_jobs, "n_jobs", low=0, integer=True)
    if n_jobs == 0:
        n_jobs = os.cpu_count() or 1
    n_slices = vol.shape[ax]
    workers = 1 if client is not None else min(n_jobs, n_slices)
    slice_shape = [d for a, d in enumerate(vol.shape) if a != ax]
    check_memory(max(min(vol.size, LEVEL_SAMPLE_VOXELS) * LEVEL_BYTES_PER_VOXEL,
                     workers * slice_bytes(*slice_shape)) + vol.size * RESULT_BYTES_PER_VOXEL,
                 f"segmenting a {' x '.join(map(str, vol.shape))} volume with {workers} "
                 "process(es)", "use fewer worker processes (--jobs)")
    report = progress or (lambda frac, msg: None)
    t_start = time.perf_counter()

    report(0.0, "gray levels")
    sample = _sample_slices(n_slices, vol.size // n_slices)
    stack = np.stack([as_image(volume_slice(vol, ax, k), name=f"slice {k}") for k in sample])
    scale = gray_scale(stack)
    level_keys = ("sigma", "density_floor", "density_saturation", "merge_k", "merge_rel",
                  "merge_floor", "n_materials")
    merged = {**SEGMENT_DEFAULTS, **params}
    levels, pixel_sigma = material_levels(stack, scale, **{k: merged[k] for k in level_keys})
    del stack
    slice_params = dict(params, n_sites=n_sites, seed=seed, gray_scale=scale, levels_255=levels)
    slice_params.pop("n_materials", None)  # fixed by the levels
    t_levels = time.perf_counter() - t_start

    keep = {int(k) for k in keep_maps}
    store = None
    if checkpoint is not None:
        store = _Checkpoint(checkpoint, vol, ax, {**SEGMENT_DEFAULTS, **params,
                                                  "n_sites": n_sites, "seed": seed})
    slices = [None] * n_slices
    if store is not None:
        for k, seg in store.load().items():
            if k not in keep:  # a figure slice is recomputed: its maps are not stored
                slices[k] = seg
    tasks = {k: (np.ascontiguousarray(volume_slice(vol, ax, k)), slice_params, k in keep)
             for k in range(n_slices) if slices[k] is None}
    resumed = n_slices - len(tasks)

    def on_done(k, seg):
        slices[k] = seg
        if store is not None:
            store.save(k, seg)
        done = sum(s is not None for s in slices)
        report(done / n_slices, f"slice {done}/{n_slices}")

    if client is not None:
        executor = "dask"
        _run_dask(tasks, client, on_done)
    elif n_jobs > 1 and len(tasks) > 1:
        executor = f"{min(n_jobs, len(tasks))} processes"
        _run_local(tasks, min(n_jobs, len(tasks)), on_done)
    else:
        executor = "serial"
        for k, task in tasks.items():
            on_done(k, _slice_result(lambda: _segment_slice(*task), k))
    factor = scale[1]
    mat_gray = levels / factor + scale[0] if factor else np.full(len(levels), scale[0])
    times = {}
    for s in slices:
        for name, t in s.diagnostics["times_s"].items():
            times[name] = times.get(name, 0.0) + t
    diagnostics = {
        "volume_shape": list(vol.shape),
        "axis": "zyx"[ax],
        "n_slices": int(n_slices),
        "executor": executor,
        "resumed_slices": int(resumed),
        "gray_rescale": {"offset": scale[0], "factor": scale[1]},
        "level_sample_slices": [int(k) for k in sample],
        "material_levels_255": [float(v) for v in levels],
        "material_noise_255": float(pixel_sigma),
        "material_gray": [float(v) for v in mat_gray],
        "n_materials": int(len(levels)),
        "n_triangles": int(sum(len(s.triangles) for s in slices)),
        "levels_time_s": t_levels,
        "slice_times_s": times,
        "wall_time_s": time.perf_counter() - t_start,
    }
    return VolumeSegmentation(slices=slices, axis=ax, material_gray=mat_gray,
                              diagnostics=diagnostics)


def volume_labels(vseg, shape):
    """Per-voxel material labels of a volume segmentation (each slice rasterised)."""
    from .metrics import label_image

    out = np.zeros(shape, np.int64)
    for k, seg in enumerate(vseg.slices):
        lab = label_image(seg.points, seg.triangles, seg.material, seg.shape)
        idx = [slice(None)] * 3
        idx[vseg.axis] = k
        out[tuple(idx)] = lab
    return out
