"""Stage 4 as a VTK filter: CVT sites -> their Delaunay triangle mesh."""
import numpy as np

from ctseg.triangulation import delaunay_mesh

from .base import CTSegAlgorithm
from .convert import _cells, _points, attach_geometry, geometry_from_field_data


class DelaunayMeshFilter(CTSegAlgorithm):
    """Delaunay triangulation of the CVT sites (:func:`ctseg.delaunay_mesh`, SPEC 4).

    The triangulation is made in the image's index coordinates, as the method defines it
    (with anisotropic spacing a Delaunay mesh in world units would differ).
    Input: CVTSitesFilter's output. Output: vtkPolyData of counter-clockwise triangles in
    world coordinates, the image geometry carried on.
    """

    def __init__(self):
        super().__init__(input_type="vtkPolyData", output_type="vtkPolyData")

    def _request(self, request, in_info, out_info):
        sites = self._input(in_info)
        geom, shape = geometry_from_field_data(sites)
        pts = np.array([sites.GetPoint(k) for k in range(sites.GetNumberOfPoints())])
        mesh = delaunay_mesh(geom.to_index(pts)[:, :2])
        out = self._output_poly(out_info)
        out.SetPoints(_points(geom.to_world(np.column_stack([mesh.points, np.zeros(len(pts))]))))
        out.SetPolys(_cells(mesh.triangles.ravel(), 3))
        attach_geometry(out, geom, shape)
        self.UpdateProgress(1.0)
