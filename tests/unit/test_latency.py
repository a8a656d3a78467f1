"""The latency experiment's reading of several demo runs (the runs themselves: tests/e2e)."""

from balltrack.experiments.latency import median_run


def summary(p50: float) -> dict:
    return {"latency_ms": {"cmd_vel": {"p50_ms": p50}}}


def test_median_run_is_a_figure_some_run_measured():
    assert median_run([summary(5.7), summary(5.3), summary(5.5)], "cmd_vel", "p50_ms") == 5.5
    assert median_run([summary(5.7)], "cmd_vel", "p50_ms") == 5.7
    # (an even count: the upper middle run, not the mean of the two)
    assert median_run([summary(5.0), summary(6.0)], "cmd_vel", "p50_ms") == 6.0
