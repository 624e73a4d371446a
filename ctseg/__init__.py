"""ctseg: segmented meshes from X-ray CT images, triangles from a slice and tetrahedra from a
volume (Yang et al. 2014, and beyond).

Each stage is a plain function on numpy arrays; :func:`segment_image` runs them all, with
the parameters of :mod:`ctseg.params`. The VTK layer is :mod:`ctseg.filters`.
"""
from .density import density_map
from .errors import CTSegError, InputError, MeshCheckError, ParameterError, ResumeError
from .params import AUTO, SegmentParams
from .sites import initial_sites, random_sites, density_random_sites, ward_sites
from .cvt import lloyd_cvt, CVTResult
from .triangulation import delaunay_mesh, TriangleMesh
from .triangle_gray import triangle_gray
from .graphcut import graphcut_split
from .recursive_cut import segment_triangles
from .labelling import label_mesh
from .pipeline import SegmentedMesh, default_n_sites, segment_image
from .tetrahedra import delaunay_tetrahedra, TetraMesh
from .tetra_gray import tetra_gray
from .pipeline3d import TetraSegmentation, segment_volume_3d
from .volume import segment_array, segment_volume

__version__ = "0.1.0"
__all__ = [
    "density_map", "initial_sites", "random_sites", "density_random_sites", "ward_sites",
    "lloyd_cvt", "CVTResult", "delaunay_mesh", "TriangleMesh", "triangle_gray",
    "graphcut_split", "segment_triangles", "label_mesh", "segment_image", "SegmentedMesh",
    "segment_volume", "segment_array", "default_n_sites", "delaunay_tetrahedra", "TetraMesh",
    "tetra_gray", "TetraSegmentation", "segment_volume_3d", "SegmentParams", "AUTO", "CTSegError",
    "InputError", "ParameterError", "MeshCheckError", "ResumeError",
]
