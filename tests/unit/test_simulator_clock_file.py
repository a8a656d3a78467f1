"""A simulator's clock across its restarts: the bound it records and where a new one starts."""

import math

import pytest

from balltrack.services.simulator.clock_file import ClockFile


def test_without_a_file_the_clock_starts_at_zero(tmp_path):
    assert ClockFile(str(tmp_path / "simulator.clock")).start() == (0, 0)


@pytest.mark.parametrize("rate_hz", [30.0, 7.0, 1.0, 1000.0])
def test_every_frame_published_before_the_next_write_is_within_the_bound(tmp_path, rate_hz):
    # The service's loop: frame after frame, a write after the first frame at or past each whole
    # second. A restart at any frame starts after the last bound written (its first frame one
    # period and one seq past it): every frame published by then must be within that bound.
    clock = ClockFile(str(tmp_path / "simulator.clock"))
    period, next_write, bound = 1.0 / rate_hz, 0.0, None
    for seq in range(1, round(3.5 * rate_hz)):
        now = seq * period
        if bound is not None:
            assert round(now * 1e9) <= bound[0] and seq <= bound[1], (seq, bound)
        if now + 1e-6 >= next_write:
            next_write = math.floor(now + 1e-6) + 1.0
            clock.record(now, seq, next_write, period)
            bound = clock.start()
            assert bound[0] >= round(now * 1e9) and bound[1] >= seq
    # (the jump at a restart: about a simulated second at most)
    assert bound[0] - round((seq * period) * 1e9) <= 2e9


@pytest.mark.parametrize("text, reason", [
    ("", "not a simulator clock"),
    ("[1, 2]", "not a simulator clock"),
    ('{"stamp": 1}', "not a simulator clock"),
    ('{"stamp": -1, "seq": 3}', "integers >= 0"),
    ('{"stamp": 1.5, "seq": 3}', "integers >= 0"),
])
def test_a_file_that_is_no_bound_is_refused_with_its_reason(tmp_path, text, reason):
    path = tmp_path / "simulator.clock"
    path.write_text(text)
    with pytest.raises(ValueError, match=reason):
        ClockFile(str(path)).start()
