"""Sub-pixel boundary placement as a VTK filter: a labelled triangle mesh + its image ->
the mesh with its boundary vertices at the ISO-50 crossings (SPEC 10)."""
from ctseg.errors import InputError
from ctseg.params import AUTO
from ctseg.stages3d import subpixel_boundary_3d
from ctseg.subpixel import subpixel_mesh

from .convert import mesh_index_coordinates
from .triangle_gray import MeshAndImageFilter


class SubpixelBoundaryFilter(MeshAndImageFilter):
    """Boundary vertices moved to where the gray crosses the mean of their two materials'
    levels (:func:`ctseg.subpixel.subpixel_mesh`), as CTSegmentFilter does last.

    Input 0: a labelled triangle mesh (GraphCutSegmentFilter's output: ``material`` and
    ``gray`` cell arrays); input 1: the slice it was labelled on (MetalStreakFilter's
    output when the streaks were corrected). Output: the mesh with moved points, ``gray``
    measured again where a vertex moved, ``material`` numbered again by ascending mean
    gray (unless GrayLevels are given), field data ``material_gray`` and
    ``subpixel_moved``. With SubpixelBoundary off the mesh passes unchanged.
    Tetrahedra over a volume (GraphCutSegmentFilter's 3D output) get
    :func:`ctseg.stages3d.subpixel_boundary_3d`, as the 3D mode does last, with the
    volume's spacing and SliverMinDihedral (no move makes a sliver).
    """

    PARAMETERS = ("subpixel_boundary", "subpixel_max_shift", "gray_levels",
                  "sliver_min_dihedral_deg")

    def _slice(self, image, geometry, xyz, triangles, arrays):
        _check_labelled(arrays)
        points = mesh_index_coordinates(xyz, geometry, image.shape)
        if not self.params.subpixel_boundary:
            return {}, {"subpixel_moved": 0.0}
        out = subpixel_mesh(image, points, triangles, arrays["gray"], arrays["material"],
                            self.params.subpixel_max_shift,
                            renumber=self.params.gray_levels == AUTO)
        return self._moved(out)

    def _volume(self, volume, spacing, points, tetrahedra, arrays):
        _check_labelled(arrays)
        if not self.params.subpixel_boundary:
            return {}, {"subpixel_moved": 0.0}
        out = subpixel_boundary_3d(volume, points, tetrahedra, arrays["gray"],
                                   arrays["material"], self.params, spacing,
                                   renumber=self.params.gray_levels == AUTO)
        return self._moved(out)

    @staticmethod
    def _moved(out):
        """Cell arrays, field data and points of a :class:`ctseg.subpixel.MovedMesh`."""
        fields = {"subpixel_moved": float(out.n_moved)}
        if out.material_gray is not None:
            fields["material_gray"] = out.material_gray
        return ({"material": out.material.astype("int32"), "gray": out.gray}, fields,
                out.points)


def _check_labelled(arrays):
    for name in ("material", "gray"):
        if name not in arrays:
            raise InputError(f"mesh: no '{name}' cell array; connect a GraphCutSegmentFilter first")
