"""VTK layer of ctseg: conversions between vtkImageData/vtkPolyData and numpy, readers and
writers. The algorithms live in :mod:`ctseg`; nothing here computes a segmentation."""
from .convert import (ImageGeometry, image_to_array, array_to_image, mesh_to_polydata,
                      boundary_to_polydata, polydata_to_arrays)
from .io import read_image, write_polydata, read_polydata, SUPPORTED_INPUTS
from .base import CTSegAlgorithm
from .segment import CTSegmentFilter

__all__ = ["ImageGeometry", "image_to_array", "array_to_image", "mesh_to_polydata",
           "boundary_to_polydata", "polydata_to_arrays", "read_image", "write_polydata",
           "read_polydata", "SUPPORTED_INPUTS", "CTSegAlgorithm", "CTSegmentFilter"]
