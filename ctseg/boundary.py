"""Material boundaries of a segmented mesh as polylines (SPEC 8)."""
import numpy as np


def material_boundary(shared_edges, adjacency, material):
    """Mesh edges whose two triangles belong to different materials.

    Parameters
    ----------
    shared_edges : (k, 2) int array_like
        Vertex pair of each adjacent triangle pair (``TriangleMesh.shared_edges``).
    adjacency : (k, 2) int array_like
        The adjacent triangle pairs.
    material : (m,) int array_like
        Material per triangle.

    Returns
    -------
    edges : (b, 2) int64 ndarray
        Vertex pairs of the boundary edges.
    sides : (b, 2) int64 ndarray
        The two materials each side, smaller first.

    Example
    -------
    >>> edges, sides = material_boundary([[1, 2]], [[0, 1]], [0, 3])
    >>> edges.tolist(), sides.tolist()
    ([[1, 2]], [[0, 3]])
    """
    mat = np.asarray(material)
    adjacency = np.asarray(adjacency, np.int64).reshape(-1, 2)
    a, b = mat[adjacency[:, 0]], mat[adjacency[:, 1]]
    diff = a != b
    sides = np.sort(np.column_stack([a[diff], b[diff]]), axis=1)
    return np.asarray(shared_edges, np.int64).reshape(-1, 2)[diff], sides.astype(np.int64)


def chain_polylines(edges, sides):
    """Chain boundary edges into polylines, one material pair at a time.

    A polyline stops where three or more boundary edges of its material pair meet or where
    it reaches the image border; closed loops repeat their first vertex at the end.

    Returns
    -------
    lines : list of (int64 ndarray of vertex indices)
    line_sides : (len(lines), 2) int64 ndarray
    """
    lines, line_sides = [], []
    edges = np.asarray(edges, np.int64).reshape(-1, 2)
    sides = np.asarray(sides, np.int64).reshape(-1, 2)
    for pair in np.unique(sides, axis=0) if len(sides) else []:
        es = edges[np.all(sides == pair, axis=1)]
        adj = {}
        for k, (u, v) in enumerate(es.tolist()):
            adj.setdefault(u, []).append(k)
            adj.setdefault(v, []).append(k)
        used = np.zeros(len(es), bool)

        def walk(start, k):
            line = [start]
            cur = start
            while True:
                used[k] = True
                u, v = es[k]
                cur = int(v if u == cur else u)
                line.append(cur)
                nxt = [j for j in adj[cur] if not used[j]]
                if len(adj[cur]) != 2 or not nxt:
                    return line
                k = nxt[0]

        # open chains start at vertices of degree != 2, then the remaining closed loops
        for v in sorted(adj, key=lambda x: (len(adj[x]) == 2, x)):
            for k in adj[v]:
                if not used[k]:
                    lines.append(np.array(walk(v, k), np.int64))
                    line_sides.append(pair)
    return lines, np.array(line_sides, np.int64).reshape(-1, 2)
