"""VTK layer of ctseg: conversions between vtkImageData/vtkPolyData/vtkUnstructuredGrid and
numpy, readers, writers (slices and 3D mode), and one VTK algorithm per stage. The
algorithms live in :mod:`ctseg`; nothing here computes a segmentation, and every filter
parameter comes from :mod:`ctseg.params`."""
from .convert import (ImageGeometry, image_to_array, array_to_image, mesh_to_polydata,
                      boundary_to_polydata, append_polydata, segmentation_to_polydata,
                      polydata_to_arrays, attach_geometry, geometry_from_field_data)
from .convert3d import (tetra_segmentation_to_vtk, material_surfaces_to_polydata,
                        grid_to_arrays)
from .readers import read_image, SUPPORTED_INPUTS
from .writers import write_mesh, write_polydata, read_polydata, MESH_FORMATS
from .writers3d import (write_tetra_mesh, write_interfaces, check_tetra_segmentation,
                        read_unstructured_grid, TETRA_FORMATS)
from .base import CTSegAlgorithm
from .density import DensityMapFilter
from .streaks import MetalStreakFilter
from .sites import CVTSitesFilter
from .triangulation import DelaunayMeshFilter, DelaunayTetraFilter
from .triangle_gray import TriangleGrayFilter
from .graphcut import GraphCutSegmentFilter
from .subpixel import SubpixelBoundaryFilter
from .boundary import MaterialBoundaryFilter
from .segment import CTSegmentFilter, segment_array

__all__ = ["ImageGeometry", "image_to_array", "array_to_image", "mesh_to_polydata",
           "boundary_to_polydata", "append_polydata", "segmentation_to_polydata",
           "polydata_to_arrays", "attach_geometry", "geometry_from_field_data", "read_image",
           "SUPPORTED_INPUTS", "write_mesh",
           "write_polydata", "read_polydata", "MESH_FORMATS", "tetra_segmentation_to_vtk",
           "material_surfaces_to_polydata", "grid_to_arrays", "write_tetra_mesh",
           "write_interfaces", "check_tetra_segmentation", "read_unstructured_grid",
           "TETRA_FORMATS", "CTSegAlgorithm",
           "MetalStreakFilter", "DensityMapFilter", "CVTSitesFilter", "DelaunayMeshFilter",
           "DelaunayTetraFilter",
           "TriangleGrayFilter", "GraphCutSegmentFilter", "SubpixelBoundaryFilter",
           "MaterialBoundaryFilter",
           "CTSegmentFilter", "segment_array"]
