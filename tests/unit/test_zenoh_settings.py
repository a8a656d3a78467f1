"""common.session: what Zenoh refuses in a config file or an endpoint becomes one line naming the
option (ZenohConfigError), before any session is opened."""

import pytest

from balltrack.common.session import ZenohConfigError, client_config, router_config


@pytest.mark.parametrize("text, reason", [
    ("{ mode: ", "line 2, column 1: expected array, boolean, null, number, object, or string"),
    ('{ mode: "client", connect: { endpoints: 5 } }', "line 1, column 41: invalid type: integer `5`"),
    ("{ bogus_key: 1 }", "line 1, column 3: unknown field `bogus_key`"),
])
def test_a_config_file_zenoh_refuses_is_one_line_with_where(tmp_path, text, reason):
    path = tmp_path / "session.json5"
    path.write_text(text + "\n")
    with pytest.raises(ZenohConfigError) as refused:
        client_config(zenoh_config_file=str(path))
    message = str(refused.value)
    assert message.startswith(f"{path}: {reason}"), message
    assert "\n" not in message and ".rs:" not in message


def test_a_missing_config_file_is_one_line(tmp_path):
    with pytest.raises(ZenohConfigError, match=r"missing\.json5: No such file or directory \(os error 2\)$"):
        client_config(zenoh_config_file=str(tmp_path / "missing.json5"))


@pytest.mark.parametrize("build, option", [
    (lambda: client_config(["tcp/127.0.0.1:7447", "127.0.0.1:7447"]), "--connect"),
    (lambda: router_config(["tcp-0.0.0.0:7447"]), "--listen"),
    (lambda: router_config(["tcp/0.0.0.0:0"], connect=["router-b"]), "--connect"),
])
def test_an_endpoint_zenoh_refuses_names_the_option(build, option):
    with pytest.raises(ZenohConfigError) as refused:
        build()
    message = str(refused.value)
    assert message.startswith(f"{option} ") and "Endpoints must be of the form <protocol>/<address>" in message
    assert "\n" not in message and ".rs:" not in message
