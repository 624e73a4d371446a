"""ctseg: segmented triangle meshes from X-ray CT images (Yang et al. 2014, and beyond).

Each stage is a plain function on numpy arrays; :func:`segment_image` runs them all.
"""
import os as _os

# Run from a source checkout (PYTHONPATH=., python -m pytest), the VTK layer lives in the
# sibling folder filters/ that the installed package maps to ctseg.filters: map it here too.
_root = _os.path.dirname(_os.path.dirname(_os.path.abspath(__file__)))
if (_os.path.isfile(_os.path.join(_root, "pyproject.toml"))
        and _os.path.isfile(_os.path.join(_root, "filters", "segment.py"))
        and not _os.path.isdir(_os.path.join(_os.path.dirname(__file__), "filters"))):
    __path__.append(_root)  # noqa: F821 - the package's own search path

from .density import density_map
from .errors import CTSegError, InputError, MeshCheckError, ParameterError, ResumeError
from .sites import initial_sites, random_sites, density_random_sites, ward_sites
from .cvt import lloyd_cvt, CVTResult
from .triangulation import delaunay_mesh, TriangleMesh
from .triangle_gray import triangle_gray
from .graphcut import graphcut_split
from .materials import segment_triangles
from .pipeline import SegmentedMesh, default_n_sites, segment_image

__version__ = "0.1.0"
__all__ = [
    "density_map", "initial_sites", "random_sites", "density_random_sites", "ward_sites",
    "lloyd_cvt", "CVTResult", "delaunay_mesh", "TriangleMesh", "triangle_gray",
    "graphcut_split", "segment_triangles", "segment_image", "SegmentedMesh",
    "default_n_sites", "CTSegError", "InputError", "ParameterError", "MeshCheckError",
    "ResumeError",
]
