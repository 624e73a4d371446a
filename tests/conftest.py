import os

import numpy as np
import pytest
from hypothesis import settings

from ctseg.phantoms import make_phantom

# The property tests draw the same examples on every run, so that CI passes or fails on
# the code alone; CTSEG_HYPOTHESIS=explore draws new ones (run it locally to look for
# counterexamples, and add each one found with @example).
settings.register_profile("ci", derandomize=True)
settings.register_profile("explore", derandomize=False)
settings.load_profile(os.environ.get("CTSEG_HYPOTHESIS", "ci"))


@pytest.fixture(scope="session")
def phantom_cache():
    cache = {}

    def get(size, seed, materials):
        key = (size, seed, tuple(materials))
        if key not in cache:
            cache[key] = make_phantom(size, seed=seed, materials=tuple(materials))
        return cache[key]

    return get


def disc_image(size=48, noise=0.0, seed=0):
    """Two materials: a bright disc on a dark background, with its truth."""
    yy, xx = np.mgrid[0:size, 0:size]
    truth = ((xx - size * 0.45) ** 2 + (yy - size * 0.55) ** 2 <= (size * 0.3) ** 2).astype(np.uint8)
    rng = np.random.default_rng(seed)
    img = 20.0 + 180.0 * truth + noise * rng.standard_normal(truth.shape)
    return img, truth


def _can_render():
    from ctseg.errors import InputError
    from ctseg.filters.figure import offscreen_window

    try:
        offscreen_window()
    except InputError:
        return False
    return True


# VTK >= 9.4 renders offscreen anywhere (EGL/OSMesa); VTK 9.2 needs a display
requires_rendering = pytest.mark.skipif(not _can_render(), reason="this VTK needs a display to render")
