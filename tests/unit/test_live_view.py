"""experiments/live_view.py: what counts as the page's annotated frame turned dark or lit."""

import numpy as np
import pytest

from balltrack.experiments.live_view import looks_dark, looks_lit


def checkered(dark: int, light: int) -> np.ndarray:
    """A floor of squares of two greys, as the simulator's in the page."""
    rows, columns = np.indices((62, 160)) // 10
    grey = np.where((rows + columns) % 2, light, dark).astype(np.uint8)
    return np.dstack([grey] * 3)


@pytest.mark.parametrize("picture, dark, lit", [
    (checkered(80, 160), False, True),           # the lit floor
    (checkered(0, 12), True, False),             # the floor with the light off
    (np.full((62, 160, 3), 255, np.uint8), False, False),  # an empty view (no picture yet)
    (np.full((62, 160, 3), 120, np.uint8), False, False),  # one plain grey: not a picture of the floor
])
def test_a_screenshot_is_judged_dark_lit_or_neither(picture, dark, lit):
    assert (looks_dark(picture), looks_lit(picture)) == (dark, lit)
