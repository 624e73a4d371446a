"""unique_ints: numpy's np.unique, by a sort."""
import numpy as np
import pytest
from hypothesis import given, strategies as st
from hypothesis.extra.numpy import arrays

from ctseg._sets import unique_ints


@given(arrays(st.sampled_from([np.int32, np.int64, np.uint8]), st.integers(0, 60),
              elements=st.integers(0, 9)))
def test_unique_ints_is_numpys_unique(values):
    out = unique_ints(values)
    assert out.dtype == values.dtype and np.array_equal(out, np.unique(values))


def test_unique_ints_of_many_keys_and_of_a_table():
    keys = np.random.default_rng(0).integers(-2 ** 40, 2 ** 40, 100_000)
    keys = np.concatenate([keys, keys[::3]])
    assert np.array_equal(unique_ints(keys), np.unique(keys))
    table = np.array([[4, 2, 4], [7, 2, -1]])
    assert unique_ints(table).tolist() == [-1, 2, 4, 7]


def test_unique_ints_refuses_floats():
    with pytest.raises(TypeError, match="integer"):
        unique_ints(np.array([0.5, 0.5]))
