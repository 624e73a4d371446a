"""The distinct values of a long integer array (private).

numpy 2.3 and later answer a plain ``np.unique(x)`` from a hash table and then sort the
distinct values, far slower on millions of distinct integer keys than one sort and a
comparison of neighbours (README, *Accuracy in 3D*, Time). Calls with ``return_index``,
``return_inverse`` or ``return_counts`` sort, and need nothing here.
"""
import numpy as np


def unique_ints(values):
    """``np.unique(values)`` for integer values: the distinct values, ascending (flattened).

    Example
    -------
    >>> unique_ints(np.array([[5, 1], [5, 3]])).tolist()
    [1, 3, 5]
    """
    v = np.ravel(values)
    if not np.issubdtype(v.dtype, np.integer):
        raise TypeError(f"unique_ints: integer values expected, got {v.dtype}")
    v = np.sort(v)
    return v[np.concatenate(([True], v[1:] != v[:-1]))] if len(v) else v
