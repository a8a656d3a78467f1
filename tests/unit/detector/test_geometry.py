"""The detector's pixel-grid helpers (geometry.py)."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from balltrack.services.detector.geometry import brightest_channel


@settings(max_examples=60, deadline=None)
@given(image=arrays(np.uint8, st.tuples(st.integers(11, 40), st.integers(11, 40), st.just(3))),
       top=st.integers(0, 10), left=st.integers(0, 10))
def test_brightest_channel_is_each_pixels_largest_channel(image, top, left):
    # (parts of a frame too: the detector passes views of a patch around a ball)
    part = image[top:, left:]
    assert np.array_equal(brightest_channel(part), part.max(axis=2))
