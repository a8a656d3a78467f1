"""README.md and docs/parameters.md stay in step with the code: parameters, keys, messages, commands."""

import dataclasses
import re

import pytest

from balltrack.common import keys as key_table
from balltrack.common.config import describe_config
from balltrack.common.messages import SCHEMAS
from balltrack.deploy import params
from tests.harness import REPO

README = (REPO / "README.md").read_text()
PARAMETERS = (REPO / "docs" / "parameters.md").read_text()


def section(service: str) -> str:
    """docs/parameters.md's parameter table of one service (from its heading to the next)."""
    match = re.search(rf"^#### {service} \(.*?(?=^#### |\Z|<!-- params:end)", PARAMETERS, re.M | re.S)
    assert match, f"docs/parameters.md has no parameter section for {service}"
    return match.group(0)


@pytest.mark.parametrize("service, module_name, class_name", params.CONFIGS)
def test_every_config_field_is_documented(service, module_name, class_name):
    table = section(service)
    missing = [field.name for field in dataclasses.fields(params.config_class(module_name, class_name))
               if f"| `{field.name}` |" not in table]
    assert not missing, (f"docs/parameters.md's {service} table lacks {missing}; "
                         "run python -m balltrack.deploy.params --write")


@pytest.mark.parametrize("markers", list(params.blocks()), ids=["parameters", "keys"])
def test_generated_tables_match_the_code(markers):
    path = params.targets()[markers]
    block = params.readme_block(path.read_text(), *markers)
    assert block is not None, f"{path.name} lacks the markers {markers}"
    assert block == params.blocks()[markers], (
        f"{path.name}'s generated tables (parameter names, types, defaults; keys) are out of step with "
        "the code; run python -m balltrack.deploy.params --write")


def test_the_parameter_tables_are_in_docs_and_linked_from_the_readme():
    assert params.targets()[(params.BEGIN, params.END)] == REPO / "docs" / "parameters.md"
    assert params.targets()[(params.KEYS_BEGIN, params.KEYS_END)] == REPO / "README.md"
    assert "(docs/parameters.md)" in README


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


def test_the_readme_is_a_short_manual():
    assert len(README.encode()) <= 25_000, "README.md is over 25,000 bytes: move reference detail to docs/"


def test_the_readme_parameter_summary_names_real_parameters():
    match = re.search(r"^## Parameters\n(.*?)(?=^## )", README, re.M | re.S)
    assert match, "README.md has no Parameters section"
    rows = dict(re.findall(r"^\| (\w+) \| (.+) \|$", match.group(1), re.M))
    rows.pop("service", None)  # (the header)
    configs = {service: params.config_class(module_name, class_name)
               for service, module_name, class_name in params.CONFIGS}
    assert set(rows) == set(configs), rows.keys()
    for service, cells in rows.items():
        names = {field.name for field in dataclasses.fields(configs[service])}
        described = describe_config(configs[service])
        choices = {str(choice) for field in described.values() for choice in field["choices"] or ()}
        unknown = set(re.findall(r"`(\w+)`", cells)) - names - choices
        assert not unknown, f"README.md's parameter summary names no {service} parameter {unknown}"


MANUALS = [REPO / "README.md", *sorted(path for path in (REPO / "docs").glob("*.md") if path.name != "results.md")]


@pytest.mark.parametrize("path", MANUALS, ids=lambda path: path.name)
def test_the_manuals_link_to_files_that_exist_and_hold_no_dated_runs(path):
    text = path.read_text()
    for target in re.findall(r"\]\(([^)#:]+?\.(?:md|png|py))(?:#[^)]*)?\)", text):
        assert (path.parent / target).exists(), f"{path.name} links to {target}, which does not exist"
    # (measurements with their dates belong in docs/results.md, generated from a run; scaling.md
    # sets the figures measured on this machine, each dated, beside what is extrapolated from them)
    if path.name == "scaling.md":
        return
    dated = re.findall(r"\b20\d\d-\d\d-\d\d\b|in one run|runs? here", text)
    assert not dated, f"{path.name} reads like a lab notebook: {dated}"
