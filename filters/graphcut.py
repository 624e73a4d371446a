"""Stages 6-7 as a VTK filter: mesh with ``gray`` + image -> one material per element
(triangles over a slice, or tetrahedra over a volume)."""
from ctseg.errors import InputError
from ctseg.labelling import label_mesh
from ctseg.labelling3d import label_tetrahedra
from ctseg.stages3d import tetra_mesh
from ctseg.triangulation import triangle_mesh

from .base import spec_names
from .convert import mesh_index_coordinates
from .triangle_gray import MeshAndImageFilter

# this filter's progress when each step of ctseg.labelling3d.label_tetrahedra starts
_STEPS_3D = {"level_check": 0.02, "graphcut": 0.05, "blur_correction": 0.45, "graphcut_2": 0.6,
             "mixed_relabel": 0.75, "iso50_relabel": 0.8, "piece_relabel": 0.82, "manifold_repair": 0.85}


class GraphCutSegmentFilter(MeshAndImageFilter):
    """Recursive graph cut of the elements into materials (SPEC 6-7 and 9.6).

    Input 0: the mesh with a ``gray`` cell array (TriangleGrayFilter's output): triangles
    (vtkPolyData) over a slice or tetrahedra (vtkUnstructuredGrid) over a volume; input 1:
    the vtkImageData, the slice or the volume, whose flat pixels give the material gray
    levels. Triangles: :func:`ctseg.label_mesh`, as the slices mode labels a slice.
    Tetrahedra: :func:`ctseg.labelling3d.label_tetrahedra` with the image's spacing, as the 3D
    mode labels them (the volume's levels, interior elements by their flat voxels, the
    blur correction in 3D, pinched edges repaired so that every material's surface is
    manifold). The 3D stage chain has no streak correction (MetalStreakFilter takes one
    slice): it gives CTSegmentFilter's Mode '3d' result with StreakCorrection off.

    Output: the mesh (of input 0's type) with a ``material`` cell array (0..K-1 by
    ascending mean gray) and field data ``material_gray`` (input units); tetrahedra also
    ``relabelled_for_manifold``. Parameters: what the labelling reads (``ctseg params``):
    the levels, graphcut and recursion groups (NumberOfMaterials, Lambda, Beta, ...; not
    WeightByEdgeLength for tetrahedra), DensityFloor and DensitySaturation (which find
    the flat pixels), and the blur correction (BlurCorrection, BlurMinSelfWeight,
    BlurMax).
    """

    PARAMETERS = spec_names("levels", "graphcut", "recursion", names=(
        "density_floor", "density_saturation", "blur_correction", "blur_min_self_weight",
        "blur_max_px"))

    @staticmethod
    def _gray(arrays):
        if "gray" not in arrays:
            raise InputError("mesh: no 'gray' cell array; connect a TriangleGrayFilter first")
        return arrays["gray"]

    def _slice(self, image, geometry, xyz, triangles, arrays):
        gray = self._gray(arrays)
        mesh = triangle_mesh(mesh_index_coordinates(xyz, geometry, image.shape), triangles)
        labels = label_mesh(image, mesh, gray, self.params)
        return ({"material": labels.material.astype("int32")},
                {"material_gray": labels.material_gray})

    def _volume(self, volume, spacing, points, tetrahedra, arrays):
        gray = self._gray(arrays)

        def step(name, fraction, fn, *args, **kwargs):
            self.UpdateProgress(_STEPS_3D.get(name, 0.0))
            return fn(*args, **kwargs)

        labels = label_tetrahedra(volume, tetra_mesh(points, tetrahedra), gray, self.params,
                                  spacing, timed=step)
        return ({"material": labels.material.astype("int32")},
                {"material_gray": labels.material_gray,
                 "relabelled_for_manifold": float(labels.relabelled)})
