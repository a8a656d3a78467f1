"""README.md stays in step with the code: parameters, keys, messages, commands."""

import dataclasses
import re

import pytest

from balltrack.common import keys as key_table
from balltrack.common.config import describe_config
from balltrack.common.messages import SCHEMAS
from balltrack.deploy import params
from tests.harness import REPO

README = (REPO / "README.md").read_text()


def section(service: str) -> str:
    """The README's parameter table of one service (from its heading to the next)."""
    match = re.search(rf"^#### {service} \(.*?(?=^#### |\Z|<!-- params:end)", README, re.M | re.S)
    assert match, f"README.md has no parameter section for {service}"
    return match.group(0)


@pytest.mark.parametrize("service, module_name, class_name", params.CONFIGS)
def test_every_config_field_is_in_the_readme(service, module_name, class_name):
    table = section(service)
    missing = [field.name for field in dataclasses.fields(params.config_class(module_name, class_name))
               if f"| `{field.name}` |" not in table]
    assert not missing, (f"README.md's {service} table lacks {missing}; "
                         "run python -m balltrack.deploy.params --write")


@pytest.mark.parametrize("markers", list(params.blocks()), ids=["parameters", "keys"])
def test_generated_tables_match_the_code(markers):
    block = params.readme_block(README, *markers)
    assert block is not None, f"README.md lacks the markers {markers}"
    assert block == params.blocks()[markers], (
        "README.md's generated tables (parameter names, types, defaults; keys) are out of step with "
        "the code; run python -m balltrack.deploy.params --write")


def test_every_row_shows_the_declared_meaning_and_bounds():
    for service, module_name, class_name in params.CONFIGS:
        cls = params.config_class(module_name, class_name)
        for name, _, _, allowed, meaning in params.rows(cls):
            declared = describe_config(cls)[name]
            assert meaning and meaning == declared["meaning"].replace("|", "\\|"), f"{service}.{name}"
            for choice in declared["choices"] or ():
                assert f"`{choice}`" in allowed, f"{service}.{name} lacks the choice {choice}"
            if declared["bounds"]:
                assert allowed == declared["bounds"], f"{service}.{name}"


def test_every_key_and_message_is_documented():
    for spec in key_table.TABLE:
        assert f"`{spec.key}`" in README, f"key {spec.key} missing from README.md"
    for name in SCHEMAS:
        assert f"**{name}**" in README, f"message {name} missing from README.md"


def test_quick_start_and_commands_are_documented():
    for text in ("./deploy/demo.sh", "./deploy/test.sh", "balltrack router", "balltrack detect",
                 "balltrack status", "balltrack echo", "balltrack hz", "balltrack config",
                 "balltrack experiment", "balltrack deploy start", "balltrack deploy stop",
                 "balltrack status --run-dir", "balltrack run detector", "balltrack topic list",
                 "balltrack pub", "balltrack bw", "balltrack delay", "balltrack config dump", "examples/subscribe_ball3d.py", "--zenoh-config",
                 "deploy/zenoh/router-cluster.json5", "deploy/zenoh/client.json5"):
        assert text in README, f"{text} missing from README.md"
    for script in ("deploy/demo.sh", "deploy/test.sh", "deploy/setup.sh", ".ci/run"):
        assert (REPO / script).stat().st_mode & 0o111, f"{script} is not executable"
