"""The detector's pixel-grid helpers (geometry.py)."""

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from balltrack.services.detector.geometry import SEPARABLE_BLUR_PIXELS, brightest_channel, gaussian_blur


@settings(max_examples=60, deadline=None)
@given(image=arrays(np.uint8, st.tuples(st.integers(11, 40), st.integers(11, 40), st.just(3))),
       top=st.integers(0, 10), left=st.integers(0, 10))
def test_brightest_channel_is_each_pixels_largest_channel(image, top, left):
    # (parts of a frame too: the detector passes views of a patch around a ball)
    part = image[top:, left:]
    assert np.array_equal(brightest_channel(part), part.max(axis=2))


@pytest.mark.parametrize("height, width", [(40, 30), (256, 256), (257, 256), (480, 640)])
@pytest.mark.parametrize("kernel", [3, 5, 9])
def test_gaussian_blur_is_opencvs_within_one_grey_level(height, width, kernel):
    """Below and above SEPARABLE_BLUR_PIXELS (where it takes the separable filter), a frame
    part or a view into one, colour or grey."""
    image = np.random.default_rng(height * width + kernel).integers(0, 256, (height + 4, width + 4, 3), np.uint8)
    for part in (image[2:-2, 2:-2], cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)[2:-2, 2:-2]):
        blurred = gaussian_blur(part, kernel)
        assert blurred.shape == part.shape and blurred.dtype == np.uint8
        expected = cv2.GaussianBlur(part, (kernel, kernel), 0)
        assert np.abs(blurred.astype(int) - expected).max() <= 1
        if height * width <= SEPARABLE_BLUR_PIXELS:
            assert np.array_equal(blurred, expected)


def test_gaussian_blur_of_kernel_1_is_the_image_itself():
    image = np.zeros((300, 300, 3), np.uint8)
    assert gaussian_blur(image, 1) is image
