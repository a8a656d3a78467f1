"""The colour mask stage (services/detector/mask.py) on synthetic frames."""

import math

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from balltrack.services.detector.config import DetectorConfig
from balltrack.services.detector.mask import (ColourMasker, brighten, check_image, ellipse_kernel, hue_mask,
                                              frame_gain, quarter_sample, ranked_value, reference_level)
from tests.unit.detector.drawing import coverage, draw_ball, floor, pitch_dark_frame, scene, to_uint8


def test_check_image_accepts_bgr_and_grey_and_rejects_the_rest():
    bgr = np.zeros((20, 30, 3), np.uint8)
    assert check_image(bgr) is bgr
    grey = np.full((20, 30), 7, np.uint8)
    expanded = check_image(grey)
    assert expanded.shape == (20, 30, 3) and (expanded == 7).all()
    assert check_image(grey[:, :, None]).shape == (20, 30, 3)
    with pytest.raises(ValueError, match="uint8"):
        check_image(np.zeros((20, 30, 3), np.float32))
    with pytest.raises(ValueError, match="uint8"):
        check_image([[0, 0, 0]])
    with pytest.raises(ValueError, match="HxWx3"):
        check_image(np.zeros((20, 30, 4), np.uint8))
    with pytest.raises(ValueError, match="too small"):
        check_image(np.zeros((7, 30, 3), np.uint8))


def test_reference_level_is_the_bright_level_capped_by_the_median():
    assert reference_level(np.full((64, 64, 3), 50, np.uint8)) == 50.0
    assert reference_level(np.zeros((64, 64, 3), np.uint8)) == 1.0  # never below 1
    # V is the brightest channel: a pure blue frame has the level of its blue
    blue = np.zeros((64, 64, 3), np.uint8)
    blue[..., 0] = 90
    assert reference_level(blue) == 90.0
    # a bright sky over a third of a dark floor: the level is at most 3x the median (the floor)
    sky = np.full((120, 64, 3), 10, np.uint8)
    sky[:40] = 200
    assert reference_level(sky) == 30.0


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), height=st.integers(1, 130), width=st.integers(1, 170),
       levels=st.integers(1, 256), share=st.floats(0.0, 1.0))
def test_ranked_value_is_numpys_partition(seed, height, width, levels, share):
    # few levels: ties at the rank itself, the case a histogram read off by one would miss
    plane = np.random.default_rng(seed).integers(0, levels, (height, width)).astype(np.uint8)
    rank = int(share * (plane.size - 1))
    assert ranked_value(plane, rank) == np.partition(plane.ravel(), rank)[rank]


def test_reference_level_ignores_isolated_bright_pixels():
    # salt noise on 3 % of a mid-grey frame (JPEG glints, hot pixels): the level is the grey's
    frame = np.full((240, 320, 3), 90, np.uint8)
    frame[::6, ::6] = 255
    assert reference_level(frame) == 90.0
    # a bright area keeps its level
    frame[:, :100] = 120
    assert reference_level(frame) == 120.0


def test_frame_gain_brings_dark_frames_to_the_target():
    config = DetectorConfig()  # gain_target 100, max_gain 64
    assert frame_gain(200.0, config) == 1.0      # bright frames are not darkened
    assert frame_gain(25.0, config) == pytest.approx(4.0)
    assert frame_gain(1.0, config) == 64.0       # at most max_gain
    assert frame_gain(1.0, DetectorConfig(max_gain=1.0)) == 1.0  # off


def test_ellipse_kernel():
    assert ellipse_kernel(0) is None and ellipse_kernel(1) is None
    kernel = ellipse_kernel(5)
    assert kernel.shape == (5, 5) and kernel[2, 2] == 1 and kernel[0, 0] == 0


def test_mask_covers_the_ball_and_nothing_else():
    u, v, radius = 200.3, 150.6, 20.0
    planes = ColourMasker(DetectorConfig()).planes(scene([(u, v, radius)]))
    assert planes.mask.dtype == np.uint8 and set(np.unique(planes.mask)) == {0, 255}
    assert planes.gain == 1.0 and not planes.dark
    ys, xs = np.nonzero(planes.mask)
    # the mask's blob is the disc, spread by the blur by about a pixel at most
    distance = np.hypot(xs - u, ys - v)
    assert distance.max() <= radius + 2.0
    area = np.count_nonzero(planes.mask)
    assert math.pi * (radius - 1) ** 2 <= area <= math.pi * (radius + 1.5) ** 2
    # the chroma plane is max - min channel: high on the felt, low on the grey floor
    assert planes.chroma[int(v), int(u)] > 100 and planes.chroma[20, 20] < 20


def test_other_hues_are_not_in_the_mask():
    image = to_uint8(draw_ball(floor(), 320.0, 240.0, 30.0, colour=(30, 120, 240)))  # orange
    assert np.count_nonzero(ColourMasker(DetectorConfig()).planes(image).mask) == 0


def test_a_hue_range_through_zero():
    image = to_uint8(draw_ball(floor(), 320.0, 240.0, 30.0, colour=(30, 30, 210)))  # red
    assert np.count_nonzero(ColourMasker(DetectorConfig()).planes(image).mask) == 0
    red = ColourMasker(DetectorConfig(h_min=170, h_max=8)).planes(image).mask
    assert red[240, 320] == 255 and red[20, 20] == 0


def test_opening_removes_specks():
    image = to_uint8(floor())
    image[100:102, 100:102] = (40, 225, 190)  # 2x2 pixels of felt
    assert np.count_nonzero(ColourMasker(DetectorConfig(blur_kernel=1)).planes(image).mask) == 0
    kept = ColourMasker(DetectorConfig(blur_kernel=1, open_kernel=0)).planes(image).mask
    assert kept[100, 100] == 255


def test_dark_frames_are_gained_before_the_colour_test():
    u, v, radius = 300.5, 260.5, 25.0
    image = scene([(u, v, radius)], brightness=0.05)
    planes = ColourMasker(DetectorConfig()).planes(image)
    assert 10.0 < planes.gain < 32.0 and not planes.dark
    # the gained frame is the input scaled by the gain; the reference is on that scale
    assert abs(int(planes.frame[20, 20, 1]) - image[20, 20, 1] * planes.gain) <= 1
    assert planes.reference == pytest.approx(min(255.0, reference_level(image) * planes.gain))
    inside = coverage(image.shape, u, v, radius - 2) > 0.99
    assert np.count_nonzero(planes.mask[inside]) > 0.95 * np.count_nonzero(inside)
    # without the gain the colour of the dark ball is rounding noise
    assert np.count_nonzero(ColourMasker(DetectorConfig(max_gain=1.0)).planes(image).mask[inside]) \
        < 0.5 * np.count_nonzero(inside)


def test_brighten_scales_clipping_pixels_only_up_to_white():
    image = np.zeros((40, 40, 3), np.uint8)
    image[:, :20] = (10, 40, 30)       # dark: plainly scaled
    image[:, 20:] = (150, 240, 215)    # pale felt, S ~96: its channels would all clip
    gained = brighten(image, 3.0, quarter_sample(image))
    assert tuple(gained[5, 5]) == (30, 120, 90)
    # the brightest channel at 255, the others in the same ratio: hue and saturation kept
    assert tuple(gained[5, 30]) == (159, 255, 228)
    # nothing clips: the plain scaling
    assert (brighten(image[:, :20], 3.0, quarter_sample(image[:, :20])) == image[:, :20] * 3).all()


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), gain=st.floats(1.01, 64.0))
def test_brighten_scales_every_clipping_pixel_as_its_float32_ratio_to_white(seed, gain):
    # a frame of every brightness (a view of a wider one, as a caller's frame may be)
    wide = (np.random.default_rng(seed).random((30, 50, 3)) ** 2 * 255).astype(np.uint8)
    image = wide[:, 5:45]
    gained = brighten(image, gain, quarter_sample(image))
    expected = cv2.convertScaleAbs(image, alpha=gain)
    value = image.max(axis=2)
    clipping = value > 255.0 / gain
    ratio = np.float32(255.0) / value[clipping].astype(np.float32)
    expected[clipping] = np.rint(image[clipping].astype(np.float32) * ratio[:, None]).astype(np.uint8)
    if float(quarter_sample(image).max()) * gain <= 255.0:
        expected = cv2.convertScaleAbs(image, alpha=gain)  # (the sample says nothing clips)
    assert np.array_equal(gained, expected)


def test_a_bright_ball_in_a_dark_frame_keeps_its_colour():
    u, v, radius = 320.5, 240.5, 30.0
    pale_felt = (150, 240, 215)
    image = to_uint8(draw_ball(floor() * 0.1, u, v, radius, colour=pale_felt, shade_floor=0.9))
    planes = ColourMasker(DetectorConfig()).planes(image)
    assert planes.gain > 2.0  # set by the dark floor
    inside = coverage(image.shape, u, v, radius - 3) > 0.99
    assert np.count_nonzero(planes.mask[inside]) > 0.95 * np.count_nonzero(inside)


def test_extremely_dark_frames_use_wider_averages():
    image = pitch_dark_frame(balls=[(300.4, 280.7, 20.0)])
    planes = ColourMasker(DetectorConfig()).planes(image)
    assert planes.dark and planes.gain >= DetectorConfig().dark_gain
    # the lit cap (upper half) is found, the black lower side is not
    assert planes.mask[270, 300] == 255
    assert planes.mask[297, 300] == 0
    off = ColourMasker(DetectorConfig(dark_gain=0.0)).planes(image)
    assert not off.dark


def test_equalise_is_identity_without_clahe():
    value = np.random.default_rng(0).integers(0, 256, (100, 120), dtype=np.uint8)
    frame = cv2.merge([value, value, value])
    assert ColourMasker(DetectorConfig(clahe_clip_limit=0.0)).equalise(value, frame) is value
    equalised = ColourMasker(DetectorConfig()).equalise(value, frame)
    assert equalised.shape == value.shape and equalised.dtype == np.uint8
    wide = np.tile(np.linspace(20, 60, 640, dtype=np.uint8), (480, 1))
    stretched = ColourMasker(DetectorConfig()).equalise(wide, cv2.merge([wide, wide, wide]))
    assert stretched.shape == wide.shape
    # local equalisation spreads a narrow range of brightness
    assert int(stretched.max()) - int(stretched.min()) > int(wide.max()) - int(wide.min())


def test_hue_mask_takes_the_range_inclusive_and_wraps_through_zero():
    hue = np.arange(180, dtype=np.uint8).reshape(1, -1)
    inside = np.flatnonzero(hue_mask(hue, DetectorConfig(h_min=25, h_max=45))[0])
    assert inside.tolist() == list(range(25, 46))
    wrapped = np.flatnonzero(hue_mask(hue, DetectorConfig(h_min=170, h_max=8))[0])
    assert wrapped.tolist() == list(range(0, 9)) + list(range(170, 180))
