import numpy as np
import pytest

from ctseg.errors import MeshCheckError
from ctseg.meshcheck import check_mesh, mesh_check_report

PTS = np.array([[0, 0], [1, 0], [0, 1], [1, 1], [2, 0], [0.5, 0.5], [2, 2]], float)
GOOD = np.array([[0, 1, 5], [1, 3, 5], [3, 2, 5], [2, 0, 5], [1, 4, 3]])


def test_good_mesh_passes():
    report = check_mesh(PTS[:6], GOOD)
    assert report["ok"] and report["faces"] == 5


@pytest.mark.parametrize("tri,key", [
    (np.vstack([GOOD, GOOD[:1]]), "duplicated_faces"),
    (np.vstack([GOOD, [[1, 3, 6]]]), "non_manifold_edges"),
    (np.vstack([GOOD[:4], [[1, 3, 4]]]), "inconsistently_oriented_edges"),
    (np.vstack([GOOD, [[0, 5, 3]]]), "non_manifold_edges"),
])
def test_defects_are_found(tri, key):
    pts = PTS
    report = mesh_check_report(pts, tri)
    assert not report["ok"] and report[key] > 0
    with pytest.raises(MeshCheckError, match=key):
        check_mesh(pts, tri)


def test_zero_area_face():
    pts = np.array([[0, 0], [1, 0], [2, 0], [0, 1]], float)
    tri = np.array([[0, 1, 3], [0, 2, 1]])
    report = mesh_check_report(pts, tri)
    assert report["degenerate_faces"] == 1 and not report["ok"]


def test_segmentation_meshes_pass(phantom_cache):
    import ctseg

    p = phantom_cache(256, 11, ("air", "aluminium", "steel"))
    seg = ctseg.segment_image(p.image)
    assert check_mesh(seg.points, seg.triangles)["ok"]
