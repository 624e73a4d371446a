"""Stages 2-3 as a VTK filter: an image with a ``density`` array -> the CVT sites."""
import numpy as np
from vtkmodules.util import numpy_support

from ctseg.cvt import lloyd_cvt
from ctseg.errors import InputError
from ctseg.params import AUTO
from ctseg.pipeline import default_n_sites
from ctseg.sites import initial_sites

from .base import CTSegAlgorithm, spec_names
from .convert import _cells, _field_array, _points, attach_geometry


class CVTSitesFilter(CTSegAlgorithm):
    """Initial sites and the pixel CVT of a density map (:func:`ctseg.initial_sites`,
    :func:`ctseg.lloyd_cvt`; SPEC 2-3).

    Input: a one-slice vtkImageData with a ``density`` point array (DensityMapFilter's
    output). Output: vtkPolyData of the sites (one vertex cell each) in world coordinates,
    with field data ``cvt_energy`` (energy per iteration), ``lloyd_iterations``,
    ``lloyd_converged`` and the image geometry (for DelaunayMeshFilter).
    Parameters (``ctseg params``): NumberOfSites, PixelsPerSite, Initialization, Seed,
    WardBlockPixels (the initial sites) and the cvt group (Tolerance, MaximumIterations).
    """

    PARAMETERS = spec_names("cvt", names=("n_sites", "pixels_per_site", "init", "seed",
                                          "ward_block_px"))

    def __init__(self):
        super().__init__(input_type="vtkImageData", output_type="vtkPolyData")

    def _request(self, request, in_info, out_info):
        _, geom, image = self._input_slice(in_info)
        dens = image.GetPointData().GetArray("density")
        if dens is None:
            raise InputError("image: no 'density' point array; connect a DensityMapFilter first")
        dims = image.GetDimensions()
        rho = numpy_support.vtk_to_numpy(dens).reshape(dims[1], dims[0])
        p = self.params
        n_sites = p.n_sites
        if n_sites == AUTO:
            n_sites = default_n_sites(rho.shape, p.pixels_per_site)
        self.UpdateProgress(0.0)
        sites0 = initial_sites(rho, n_sites, init=p.init, seed=p.seed,
                               ward_block_px=p.ward_block_px)
        self.UpdateProgress(0.2)
        cvt = lloyd_cvt(rho, sites0, tol_px=p.tol_px, max_iter=p.max_iter,
                        progress=lambda it, n: self.UpdateProgress(0.2 + 0.8 * it / max(n, 1)))
        out = self._output_poly(out_info)
        xyz = geom.to_world(np.column_stack([cvt.sites, np.zeros(len(cvt.sites))]))
        out.SetPoints(_points(xyz))
        out.SetVerts(_cells(np.arange(len(xyz)), 1))
        attach_geometry(out, geom, rho.shape)
        _field_array(out, "cvt_energy", np.asarray(cvt.energy, float))
        _field_array(out, "lloyd_iterations", float(cvt.n_iter))
        _field_array(out, "lloyd_converged", float(cvt.converged))
        self.UpdateProgress(1.0)
