"""The fuzz campaign's quick version (``balltrack experiment fuzz --quick``): 300 generated
messages to every key and queryable of the four real service processes, then no crash, every
query answered and valid messages still served. (About 20-60 s on two cores.)"""

import pytest

from balltrack.experiments import fuzz
from balltrack.experiments.base import Options

# The quick tier leaves the campaign to the whole suite and keeps malformed input to real services
# (test_malformed_input.py) and mutated messages to the decoder (tests/unit/test_messages_properties.py).
pytestmark = pytest.mark.slow


@pytest.mark.timeout(240)  # the quick campaign fits within about a minute; this only stops a hang
def test_quick_fuzz_campaign_crashes_nothing(tmp_path):
    result = fuzz.run(Options(out=tmp_path, quick=True, progress=False))
    figures = result.figures
    assert figures["fuzz/crashes"] == 0
    assert figures["fuzz/unanswered_queries"] == 0
    data_keys, query_keys = fuzz.targets(fuzz.SERVICES)
    for key, _ in data_keys:
        assert figures[f"fuzz/sent/{key}"] == 300
    assert figures["fuzz/sent/sim/control"] == 300
    assert figures["fuzz/sent/simulator/config"] == 300
    served = {name: value for name, value in figures.items() if name.startswith("fuzz/served_after/")}
    assert served and all(value is True for value in served.values()), served
    goals = {goal.name: goal.passed for goal in result.goals}
    assert goals["fuzz/crashes"] and goals["fuzz/answered"] and goals["fuzz/served_after"]
