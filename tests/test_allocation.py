"""The 3D mode's allocation settings: large arrays on the heap within the block, glibc's and
numpy's settings back afterwards, nested blocks and errors included."""
import ctypes

import numpy as np
import pytest

from ctseg import _allocation
from ctseg._allocation import bulk_allocations, release_free_heap


class _MallInfo2(ctypes.Structure):
    _fields_ = [(name, ctypes.c_size_t) for name in (
        "arena", "ordblks", "smblks", "hblks", "hblkhd", "usmblks", "fsmblks", "uordblks",
        "fordblks", "keepcost")]


def _mapped_blocks():
    """glibc's count of blocks held in mappings of their own (mallinfo2's hblks)."""
    libc = _allocation._LIBC
    if libc is None or not hasattr(libc, "mallinfo2"):
        pytest.skip("not glibc 2.33 or later")
    libc.mallinfo2.restype = _MallInfo2
    return libc.mallinfo2().hblks


def _mapped_while_held(n_bytes=64 * 2 ** 20):
    """How many more mapped blocks there are while a fresh array of ``n_bytes`` lives."""
    before = _mapped_blocks()
    a = np.ones(n_bytes // 8)
    held = _mapped_blocks()
    del a
    return held - before


def _advice():
    """numpy's huge-page advice now (set to itself to read it)."""
    setter = _allocation._SET_ADVICE
    if setter is None:
        pytest.skip("this numpy has no huge-page switch")
    value = setter(True)
    setter(value)
    return bool(value)


def test_large_arrays_come_from_the_heap_only_within_the_block():
    assert _mapped_while_held() == 1  # glibc's default: a block of its own
    with bulk_allocations():
        assert _mapped_while_held() == 0
        release_free_heap()
        assert _mapped_while_held() == 0
    assert _mapped_while_held() == 1


def test_numpy_advice_is_off_within_and_restored_after_nesting_and_errors():
    before = _advice()
    with pytest.raises(RuntimeError):
        with bulk_allocations():
            with bulk_allocations():
                assert _advice() is False
            assert _advice() is False  # the outer block still holds
            raise RuntimeError("stage failed")
    assert _advice() is before
    assert _allocation._depth == 0


def test_a_decorated_function_keeps_its_name_and_result():
    @bulk_allocations()
    def work(n):
        """Doc."""
        assert _allocation._depth == 1
        return float(np.arange(n, dtype=float).sum())
    assert work(1000) == 499500.0 and work.__name__ == "work" and work.__doc__ == "Doc."
    assert _allocation._depth == 0
