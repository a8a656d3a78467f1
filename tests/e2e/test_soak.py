"""The soak's quick version (``balltrack experiment soak --quick``): the real router and four
services chase a circling ball for two minutes; nothing restarts, the frames keep flowing and
no process's resident memory grows by 20 MB after the first minute."""

import pytest

from balltrack.experiments import soak
from balltrack.experiments.base import Options

pytestmark = pytest.mark.slow


@pytest.mark.timeout(420)  # two measured minutes plus startup; this only stops a hang
def test_two_minute_soak_restarts_nothing_and_does_not_grow(tmp_path):
    result = soak.run(Options(out=tmp_path, quick=True, progress=False))
    figures = result.figures
    assert figures["soak/restarts/total"] == 0, figures
    for minute in (1, 2):
        assert figures[f"soak/minute_{minute:02d}/frames"] > 0, figures
        assert figures[f"soak/minute_{minute:02d}/positions"] > 0, figures
    for process in soak.PROCESSES:
        growth = figures[f"soak/rss_growth_mb/{process}"]
        assert growth is not None and growth < soak.MEMORY_GROWTH_LIMIT_MB, (process, figures)
    goals = {goal.name: goal.passed for goal in result.goals}
    assert goals["soak/restarts"] and goals["soak/memory"], result.goals
