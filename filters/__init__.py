"""VTK layer of ctseg: conversions between vtkImageData/vtkPolyData and numpy, readers,
writers, and one VTK algorithm per stage. The algorithms live in :mod:`ctseg`; nothing here
computes a segmentation."""
from .convert import (ImageGeometry, image_to_array, array_to_image, mesh_to_polydata,
                      boundary_to_polydata, append_polydata, segmentation_to_polydata,
                      polydata_to_arrays)
from .readers import read_image, SUPPORTED_INPUTS
from .writers import write_mesh, write_polydata, read_polydata, MESH_FORMATS
from .base import CTSegAlgorithm
from .density import DensityMapFilter
from .streaks import MetalStreakFilter
from .sites import CVTSitesFilter
from .triangulation import DelaunayMeshFilter
from .triangle_gray import TriangleGrayFilter
from .graphcut import GraphCutSegmentFilter
from .boundary import MaterialBoundaryFilter
from .segment import CTSegmentFilter

__all__ = ["ImageGeometry", "image_to_array", "array_to_image", "mesh_to_polydata",
           "boundary_to_polydata", "append_polydata", "segmentation_to_polydata",
           "polydata_to_arrays", "read_image", "SUPPORTED_INPUTS", "write_mesh",
           "write_polydata", "read_polydata", "MESH_FORMATS", "CTSegAlgorithm",
           "MetalStreakFilter", "DensityMapFilter", "CVTSitesFilter", "DelaunayMeshFilter",
           "TriangleGrayFilter", "GraphCutSegmentFilter", "MaterialBoundaryFilter",
           "CTSegmentFilter"]
