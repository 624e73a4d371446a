"""Stages 2-3 as a VTK filter: an image (a slice or a volume) with a ``density`` array ->
the CVT sites."""
import numpy as np
from vtkmodules.util import numpy_support

from ctseg.cvt import lloyd_cvt
from ctseg.errors import InputError
from ctseg.params import AUTO
from ctseg.site_budget import site_budget
from ctseg.sites import initial_sites
from ctseg.stages3d import cvt_sites_3d, n_sites_3d

from .base import CTSegAlgorithm, spec_names
from .convert import _cells, _field_array, _points, attach_geometry
from .density import image_input

BOX_POINTS = "ctseg_box_coordinates"
"""Point array of the 3D stages' outputs (sites, tetrahedra): each point's physical box
coordinates ((i, j, k) index x spacing) exactly as the ctseg stage made them, so that the
next stage computes on the same bits as CTSegmentFilter (world -> box coordinates loses the
last bits, and the Delaunay tetrahedra of the box-aligned face and edge sites change with
them)."""


def add_box_points(data, box):
    """Record ``box`` (n, 3), the physical box coordinates of ``data``'s points."""
    arr = numpy_support.numpy_to_vtk(np.ascontiguousarray(box, np.float64), deep=True)
    arr.SetName(BOX_POINTS)
    data.GetPointData().AddArray(arr)


def box_points(data, geometry, shape, name="mesh", tol_px=1e-6):
    """The physical box coordinates ((i, j, k) index x spacing) of ``data``'s points over a
    volume of ``shape`` (nz, ny, nx): the recorded :data:`BOX_POINTS` while the points are
    still where they map to (1e-9 of the extent), else from the world points through
    ``geometry`` (moved points are taken as they are).

    Raises
    ------
    InputError
        No points, or points outside the volume's box of voxel centres.
    """
    if data.GetPoints() is None or data.GetNumberOfPoints() == 0:
        raise InputError(f"{name}: no points")
    xyz = np.array(numpy_support.vtk_to_numpy(data.GetPoints().GetData()), np.float64)
    spacing = np.asarray(geometry.spacing, float)
    top = np.array(tuple(shape)[::-1], float) - 1.0
    ijk = geometry.to_index(xyz)
    if ijk.min() < -tol_px or np.any(ijk > top + tol_px):
        raise InputError(f"{name}: its points lie outside the volume's box of voxel centres")
    rec = data.GetPointData().GetArray(BOX_POINTS)
    if rec is not None and rec.GetNumberOfComponents() == 3 and rec.GetNumberOfTuples() == len(xyz):
        box = np.array(numpy_support.vtk_to_numpy(rec), np.float64)
        extent = 1.0 + np.abs(xyz).max() + float(np.linalg.norm(top * spacing))
        if np.abs(geometry.to_world(box / spacing) - xyz).max() <= 1e-9 * extent:
            return box
    return np.clip(ijk, 0.0, top) * spacing


class CVTSitesFilter(CTSegAlgorithm):
    """Initial sites and the CVT of a density map (SPEC 2-3 and 9.2-9.3).

    Input: a vtkImageData with a ``density`` point array (DensityMapFilter's output). One
    slice: :func:`ctseg.initial_sites` and the pixel CVT :func:`ctseg.lloyd_cvt`, as the
    slices mode. A volume: :func:`ctseg.stages3d.cvt_sites_3d`
    (:func:`ctseg.sites.initial_sites_3d` and the voxel CVT
    :func:`ctseg.cvt3d.lloyd_cvt_3d` with the image's spacing), as the 3D mode; its sites
    include the corners, edge and face sites that keep the box covered.

    Output: vtkPolyData of the sites (one vertex cell each) in world coordinates (the
    image's origin, spacing and direction), with field data ``cvt_energy`` (energy per
    iteration), ``lloyd_iterations``, ``lloyd_converged`` and the image geometry and shape
    (for DelaunayMeshFilter, or DelaunayTetraFilter for a volume's sites); a volume's
    sites also have a ``site_class`` point array (0 free, 1 face, 2 edge, 3 corner,
    :data:`ctseg.cvt3d.SITE_CLASSES`), the exact box coordinates (:data:`BOX_POINTS`)
    and field data ``empty_regions``.
    Parameters (``ctseg params``): NumberOfSites (per slice, or for the whole volume);
    when it is auto, the count comes from the input image's gray scalars as the composite
    counts them: :func:`ctseg.site_budget.site_budget` for a slice (SiteRule,
    PixelsPerSite, BoundaryPxPerSite, MinPixelsPerSite, DensitySigma), ``site_budget_3d``
    for a volume (SiteRule, VoxelsPerSite, MinPixelsPerSite, DensitySigma); Initialization,
    Seed, WardBlockPixels (the initial sites) and the cvt group (Tolerance,
    MaximumIterations).
    """

    PARAMETERS = spec_names("cvt", names=("n_sites", "pixels_per_site", "site_rule",
                                          "boundary_px_per_site", "min_pixels_per_site",
                                          "density_sigma_px", "voxels_per_site", "init",
                                          "seed", "ward_block_px"))

    def __init__(self):
        super().__init__(input_type="vtkImageData", output_type="vtkPolyData")

    def _request(self, request, in_info, out_info):
        arr, geom, image = image_input(in_info, array_name=self.gray_array_name())
        dens = image.GetPointData().GetArray("density")
        if dens is None:
            raise InputError("image: no 'density' point array; connect a DensityMapFilter first")
        rho = numpy_support.vtk_to_numpy(dens).reshape(arr.shape)
        p = self.params
        steps = lambda it, n: self.UpdateProgress(0.2 + 0.8 * it / max(n, 1))
        self.UpdateProgress(0.0)
        if rho.ndim == 3:
            n_sites = n_sites_3d(arr, p)[0]
            cvt = cvt_sites_3d(np.asarray(rho, np.float64), p, geom.spacing, n_sites=n_sites,
                               progress=steps)
            xyz = geom.to_world(cvt.sites / np.asarray(geom.spacing, float))
            box = cvt.sites
        else:
            n_sites = p.n_sites
            if n_sites == AUTO:
                n_sites = site_budget(np.asarray(arr, np.float64), p.pixels_per_site,
                                      p.boundary_px_per_site, p.min_pixels_per_site,
                                      p.site_rule, p.density_sigma_px)[0]
            sites0 = initial_sites(rho, n_sites, init=p.init, seed=p.seed,
                                   ward_block_px=p.ward_block_px)
            self.UpdateProgress(0.2)
            cvt = lloyd_cvt(rho, sites0, tol_px=p.tol_px, max_iter=p.max_iter, progress=steps)
            xyz = geom.to_world(np.column_stack([cvt.sites, np.zeros(len(cvt.sites))]))
        out = self._output_poly(out_info)
        out.SetPoints(_points(xyz))
        out.SetVerts(_cells(np.arange(len(xyz)), 1))
        attach_geometry(out, geom, rho.shape)
        _field_array(out, "cvt_energy", np.asarray(cvt.energy, float))
        _field_array(out, "lloyd_iterations", float(cvt.n_iter))
        _field_array(out, "lloyd_converged", float(cvt.converged))
        if rho.ndim == 3:
            _field_array(out, "empty_regions", float(cvt.empty_regions))
            classes = numpy_support.numpy_to_vtk(np.asarray(cvt.site_class, np.int32), deep=True)
            classes.SetName("site_class")
            out.GetPointData().AddArray(classes)
            add_box_points(out, box)
        self.UpdateProgress(1.0)
