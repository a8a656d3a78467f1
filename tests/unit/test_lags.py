"""experiments.lags.ArrivalLags: frame -> derived message lags as the soak and viewer_cost read them."""

import pytest

from balltrack.experiments.lags import ArrivalLags


def test_lags_are_matched_by_key_and_taken_once():
    lags = ArrivalLags()
    lags.start(1, 10.0)
    lags.start(1, 10.5)  # the same frame again: its first arrival counts
    lags.start(2, 11.0)
    lags.end(1, 10.25)
    lags.end(3, 12.0)  # nothing started under 3
    assert lags.take() == [pytest.approx(0.25)]
    lags.end(2, 11.5)
    lags.end(2, 11.75)  # a key may match twice unless once=True
    assert lags.take() == [pytest.approx(0.5), pytest.approx(0.75)]
    assert lags.take() == []


def test_once_and_the_bound_on_waiting_keys():
    lags = ArrivalLags(keep=4)
    for key in range(5):
        lags.start(key, float(key))
    lags.end(0, 9.0)  # the older half went when the fifth key came
    lags.end(4, 4.5, once=True)
    lags.end(4, 4.75, once=True)
    assert lags.take() == [pytest.approx(0.5)]
