"""Stages 2-3 as a VTK filter: an image with a ``density`` array -> the CVT sites."""
import numpy as np
from vtkmodules.util import numpy_support

from ctseg.cvt import lloyd_cvt
from ctseg.errors import InputError
from ctseg.pipeline import default_n_sites
from ctseg.sites import initial_sites

from .base import CTSegAlgorithm, parameter
from .convert import _cells, _points


class CVTSitesFilter(CTSegAlgorithm):
    """Ward-initialised pixel CVT of a density map (:func:`ctseg.ward_sites`,
    :func:`ctseg.lloyd_cvt`; SPEC 2-3).

    Input: a one-slice vtkImageData with a ``density`` point array (DensityMapFilter's
    output). Output: vtkPolyData of the sites (one vertex cell each) in world coordinates,
    with field data ``cvt_energy`` (energy per iteration), ``lloyd_iterations``,
    ``lloyd_converged`` and the image geometry (for DelaunayMeshFilter).
    Parameters: NumberOfSites (0 = one per 128 pixels), Seed, Initialization ('ward',
    'random', 'density_random'), Tolerance (px, 0.01), MaximumIterations (200).
    """

    def __init__(self):
        super().__init__(input_type="vtkImageData", output_type="vtkPolyData")
        self._n_sites, self._seed, self._init = 0, 0, "ward"
        self._tol, self._max_iter = 0.01, 200

    SetNumberOfSites, GetNumberOfSites = parameter("_n_sites", int, "0 = one per 128 pixels")
    SetSeed, GetSeed = parameter("_seed", int, "seed of the random initialisations")
    SetInitialization, GetInitialization = parameter("_init", str, "'ward', 'random' or 'density_random'")
    SetTolerance, GetTolerance = parameter("_tol", float, "Lloyd stops below this site move, px")
    SetMaximumIterations, GetMaximumIterations = parameter("_max_iter", int, "Lloyd iteration cap")

    def _request(self, request, in_info, out_info):
        _, geom, image = self._input_slice(in_info)
        dens = image.GetPointData().GetArray("density")
        if dens is None:
            raise InputError("image: no 'density' point array; connect a DensityMapFilter first")
        dims = image.GetDimensions()
        rho = numpy_support.vtk_to_numpy(dens).reshape(dims[1], dims[0])
        n_sites = self._n_sites or default_n_sites(rho.shape)
        self.UpdateProgress(0.0)
        sites0 = initial_sites(rho, n_sites, method=self._init, seed=self._seed)
        self.UpdateProgress(0.2)
        cvt = lloyd_cvt(rho, sites0, tol=self._tol, max_iter=self._max_iter,
                        progress=lambda it, n: self.UpdateProgress(0.2 + 0.8 * it / max(n, 1)))
        out = self._output_poly(out_info)
        xyz = geom.to_world(np.column_stack([cvt.sites, np.zeros(len(cvt.sites))]))
        out.SetPoints(_points(xyz))
        out.SetVerts(_cells(np.arange(len(xyz)), 1))
        geom.attach(out, rho.shape)
        for name, values in (("cvt_energy", np.asarray(cvt.energy, float)),
                             ("lloyd_iterations", np.array([cvt.n_iter], float)),
                             ("lloyd_converged", np.array([float(cvt.converged)]))):
            arr = numpy_support.numpy_to_vtk(values, deep=True)
            arr.SetName(name)
            out.GetFieldData().AddArray(arr)
        self.UpdateProgress(1.0)
