"""3D volumes: the choice of mode ('auto', 'slices', '3d'; 3D itself is
:mod:`ctseg.pipeline3d`) and slices mode (SPEC 8): one gray map and one set of material
levels for the whole volume, slices segmented in this process, in local worker processes
or on a Dask cluster, with the same result whichever runs them."""
import os
import time
from dataclasses import dataclass, field

import numpy as np

from ._validate import as_volume, check_value_range
from .errors import CTSegError, InputError, ParameterError
from .geometry import slice_axis, volume_slice
from .levels import LEVEL_SAMPLE_VOXELS, volume_levels
from .params import AUTO, resolve
from .checkpoint import Checkpoint
from .pipeline import segment_image
from .pipeline3d import segment_volume_3d
from .resources import (LEVEL_BYTES_PER_VOXEL, RESULT_BYTES_PER_VOXEL, VOLUME_3D_BYTES_PER_VOXEL,
                        check_memory, fits_in_memory, slice_bytes)

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


def _segment_slice(image, params, extra, keep_maps=False):
    """Worker: one slice; the per-pixel maps (as large as the slice) dropped unless asked."""
    seg = segment_image(image, params, **extra)
    if not keep_maps:
        seg.density = None
        seg.cvt_labels = None
        seg.corrected_image = None
    return seg


def _run_local(tasks, n_jobs, on_done):
    """Run ``{k: task}`` in worker processes; ``on_done(k, seg)`` as each finishes."""
    from concurrent.futures import ProcessPoolExecutor, as_completed
    import multiprocessing

    # fork where there is one: spawn and forkserver start sys.executable, which inside
    # ParaView or Slicer is the application itself, and re-run the caller's __main__
    method = "fork" if "fork" in multiprocessing.get_all_start_methods() else "spawn"
    pool = ProcessPoolExecutor(max_workers=n_jobs, mp_context=multiprocessing.get_context(method),
                               initializer=_worker_init)
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


def _worker_init():
    """Workers leave Ctrl-C to the parent, which stops the run and reports once (a
    terminal sends SIGINT to the whole process group), and run the serial kernels
    (:data:`ctseg._threads.enabled`: a forked child must not start numba's threads)."""
    import signal

    from . import _threads

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    _threads.enabled = False


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
        except (OSError, TimeoutError, ValueError) as exc:  # ValueError: a malformed address
            raise ParameterError(f"client: cannot reach the Dask scheduler at {client} ({exc})") from None
    try:
        keys = list(tasks)
        # slices go to the workers as data, not inside the task graph
        images = client.scatter([tasks[k][0] for k in keys])
        futures = client.map(_segment_slice, images, *([tasks[k][i] for k in keys]
                                                        for i in (1, 2, 3)), pure=False)
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


def _slice_result(get, k):
    try:
        return get()
    except CTSegError as exc:
        raise type(exc)(f"slice {k}: {exc}") from exc


def segment_volume(volume, params=None, *, spacing=None, client=None, progress=None,
                   keep_maps=(), checkpoint=None, **overrides):
    """Segment a 3D volume into tetrahedra (mode '3d') or, slice by slice, into triangle
    meshes with one numbering of the materials for the whole volume (mode 'slices'); mode
    'auto', the default, chooses by :func:`volume_mode`.

    In slices mode the gray map onto 0-255 and the material levels are measured once on the volume
    (:func:`ctseg.levels.volume_levels`), then every slice is
    segmented against them (:func:`ctseg.segment_image` with ``gray_scale`` and
    ``levels_255``): material k is the same material in every slice, whether or not a
    slice holds it. A volume of one slice is a 2D problem with the volume's numbering.

    Parameters
    ----------
    volume : (nz, ny, nx) array_like
        The CT volume (a (rows, cols) array is one slice).
    params : ctseg.params.SegmentParams or dict, optional
        All parameters; ``overrides`` change single ones by name. ``axis`` ('z', 'y', 'x';
        or 0, 1, 2 in numpy order) is the slice axis (see
        :func:`ctseg.geometry.volume_slice`), ``n_jobs`` the local worker processes
        (1 = this process; 'auto' = one per CPU core); ``n_sites`` counts per slice.
    client : distributed.Client or str, optional
        A Dask client, or a scheduler address to connect to for this call; slices then run
        on that cluster and ``n_jobs`` is ignored.
    progress : callable, optional
        ``progress(fraction_done, message)`` after each slice.
    keep_maps : iterable of int
        Slices whose density and CVT maps are kept (for a figure); the others drop them.
    spacing : (3,) array_like, optional
        Voxel size along x, y, z (default 1); used by the 3D mode, whose distances and
        volumes are physical.
    checkpoint : str or path-like, optional
        A folder where every finished slice is saved at once; slices already there, from
        a run on the same volume with the same parameters, are loaded instead of being
        computed again (resume after an interrupt or a failure). A folder from another
        input or other parameters raises ResumeError saying what differs.

    Returns
    -------
    VolumeSegmentation (slices), or ctseg.pipeline3d.TetraSegmentation (3D:
        :func:`ctseg.pipeline3d.segment_volume_3d`, tetrahedra and closed surfaces).

    Raises
    ------
    InputError
        Not a 3D (or 2D) finite numeric array; a slice's error names the slice.
    ParameterError
        Unknown parameter or a value out of its range.

    Example
    -------
    >>> from ctseg.phantoms import make_volume
    >>> vseg = segment_volume(make_volume(3, 48).image, mode="slices", n_sites=120, n_jobs=1)
    >>> len(vseg.slices)
    3
    """
    if "axis" in overrides and not isinstance(overrides["axis"], str):
        overrides["axis"] = "zyx"[slice_axis(overrides["axis"])]
    p = resolve(params, **overrides)
    slices_for = [name for name, given in (("client", client is not None), ("keep_maps", bool(keep_maps)),
                                          ("checkpoint", checkpoint is not None)) if given]
    shape = np.shape(volume)
    mode, mode_note = volume_mode(shape, p.mode, slices_for)
    p = p.replace(mode=mode, axis=volume_slice_axis(shape, p.axis))  # as run: report, resume key
    if mode == "3d":
        check_memory(int(np.prod(shape)) * VOLUME_3D_BYTES_PER_VOXEL,
                     f"meshing a {' x '.join(map(str, shape))} volume in 3D",
                     "crop or downsample it, or use slices mode")
        return segment_volume_3d(volume, p, spacing=spacing, progress=progress)
    vol = as_volume(volume)
    check_value_range(vol, "volume")
    ax = slice_axis(p.axis)
    n_jobs = (os.cpu_count() or 1) if p.n_jobs == AUTO else p.n_jobs
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
    scale, levels, pixel_sigma, sample = volume_levels(vol, p, ax)
    slice_params = p.replace(n_materials=AUTO)  # fixed by the levels
    extra = dict(gray_scale=scale, levels_255=levels)
    t_levels = time.perf_counter() - t_start

    keep = {int(k) for k in keep_maps}
    store = None
    if checkpoint is not None:
        store = Checkpoint(checkpoint, vol, p)
    slices = [None] * n_slices
    if store is not None:
        for k, seg in store.load().items():
            if k not in keep:  # a figure slice is recomputed: its maps are not stored
                slices[k] = seg
    tasks = {k: (np.ascontiguousarray(volume_slice(vol, ax, k)), slice_params, extra, k in keep)
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
        "mode": "slices",
        "mode_note": mode_note,
        "axis": "zyx"[ax],
        "n_slices": int(n_slices),
        "executor": executor,
        "resumed_slices": int(resumed),
        "gray_rescale": {"offset": scale[0], "factor": scale[1]},
        "level_sample_slices": [int(k) for k in sample],
        "material_levels_255": [float(v) for v in levels],
        "material_noise_255": float(pixel_sigma),
        "material_gray": [float(v) for v in mat_gray],
        "parameters": p.to_dict(),
        "n_materials": int(len(levels)),
        "n_triangles": int(sum(len(s.triangles) for s in slices)),
        "levels_time_s": t_levels,
        "slice_times_s": times,
        "wall_time_s": time.perf_counter() - t_start,
    }
    return VolumeSegmentation(slices=slices, axis=ax, material_gray=mat_gray,
                              diagnostics=diagnostics)


def segment_array(array, params=None, *, spacing=None, progress=None, client=None,
                  keep_maps=(), checkpoint=None, **overrides):
    """Segment a slice or a volume: :func:`ctseg.segment_image` for a 2D array,
    :func:`segment_volume` for a 3D one (the one dispatch the command line, the VTK filter
    and the Slicer module share).

    Parameters
    ----------
    array : (rows, cols) or (nz, ny, nx) array_like
    params, spacing, progress, overrides
        As in :func:`segment_volume`.
    client, keep_maps, checkpoint
        Volumes only, as in :func:`segment_volume`.

    Returns
    -------
    SegmentedMesh, VolumeSegmentation or ctseg.pipeline3d.TetraSegmentation

    Raises
    ------
    InputError
        Mode '3d' for a single slice; and as :func:`segment_volume`.

    Example
    -------
    >>> import numpy as np
    >>> img = np.zeros((30, 30)); img[8:22, 8:22] = 1.0
    >>> type(segment_array(img, n_sites=40)).__name__
    'SegmentedMesh'
    """
    arr = np.asarray(array)
    if arr.ndim == 2:
        if resolve(params, **overrides).mode == "3d":
            raise InputError(f"mode '3d': the input is a single {arr.shape[0]} x {arr.shape[1]} "
                             "slice; 3D mode needs a volume (use mode 'auto' or 'slices' for a slice)")
        return segment_image(arr, params, progress=progress, **overrides)
    return segment_volume(arr, params, spacing=spacing, client=client, progress=progress,
                          keep_maps=keep_maps, checkpoint=checkpoint, **overrides)


def volume_slice_axis(shape, axis):
    """The slice axis ('z', 'y' or 'x') slices mode uses for a volume of ``shape``: ``axis``,
    except that a volume 1 voxel thin is sliced across that axis (slices along another
    would be 1 voxel wide); a (rows, cols) shape is one z slice.

    Example
    -------
    >>> volume_slice_axis((40, 64, 64), "z"), volume_slice_axis((40, 1, 64), "z")
    ('z', 'y')
    """
    shape = tuple(shape) if len(shape) == 3 else (1, *shape)
    if min(shape) == 1 and shape[slice_axis(axis)] > 1:
        return "zyx"[list(shape).index(1)]
    return axis


def volume_mode(shape, mode=AUTO, slices_for=()):
    """How an input of ``shape`` is meshed: in 3D ('3d') or slice by slice ('slices').

    An explicit 'slices' or '3d' is kept (3D mode refuses an input thinner than 2 voxels
    along any axis). 'auto' gives 'slices' to a (rows, cols) input, to a volume 1 voxel
    thin along an axis (sliced across that axis), and where an option only slices mode
    has is given (``slices_for``: resuming, a Dask cluster, boundary polylines...); else
    '3d' where the 3D mode fits in the memory available
    (:data:`ctseg.resources.VOLUME_3D_BYTES_PER_VOXEL` per voxel), 'slices' where not.

    Parameters
    ----------
    shape : tuple of int
        The input's shape, (rows, cols) or (nz, ny, nx).
    mode : {'auto', 'slices', '3d'}
    slices_for : sequence of str
        The names of the given options that only slices mode has.

    Returns
    -------
    mode : {'slices', '3d'}
    note : str
        Why 'auto' chose slices for a volume 3D mode could mesh ('' otherwise).

    Example
    -------
    >>> volume_mode((40, 64, 64)), volume_mode((1, 64, 64))[0], volume_mode((64, 64))[0]
    (('3d', ''), 'slices', 'slices')
    >>> volume_mode((40, 64, 64), slices_for=["--resume"])
    ('slices', "mode auto: slices, for --resume (slices mode's; mode 3d meshes the volume in 3D without it)")
    """
    shape = tuple(int(n) for n in shape)
    if mode != AUTO:
        return mode, ""
    if len(shape) == 2:
        return "slices", ""
    if min(shape) < 2:  # a slice in a volume's clothes
        return "slices", ""
    if slices_for:
        return "slices", (f"mode auto: slices, for {', '.join(slices_for)} (slices mode's; "
                          "mode 3d meshes the volume in 3D without it)")
    needed = int(np.prod(shape)) * VOLUME_3D_BYTES_PER_VOXEL
    fits, have = fits_in_memory(needed)
    if not fits:
        return "slices", (f"mode auto: slices, 3D mode would need about {needed / 2 ** 30:.1f} "
                          f"GiB of memory and {have / 2 ** 30:.1f} GiB are available")
    return "3d", ""
