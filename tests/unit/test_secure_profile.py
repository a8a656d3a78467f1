"""balltrack secure init: the files, their modes, the certificates and the access rules."""

import argparse
import ipaddress
import json
import stat

import pytest
import zenoh
from cryptography import x509
from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

from balltrack.cli import main
from balltrack.common import keys as key_table
from balltrack.common.keys import SERVICES
from balltrack.common.session import load_config_file, secure_client_path, served_namespace
from balltrack.deploy.secure import (FLEET_ROLES, ROBOT_ROLES, ROLES, ProfileError, access_control, init_profile,
                                     parse_hosts, parse_robots, permissions)


@pytest.fixture(scope="module")
def profile(tmp_path_factory):
    directory = tmp_path_factory.mktemp("profile") / "secure"
    init_profile(directory, ["robot", "192.168.1.10"])
    return directory


def mode(path) -> int:
    return stat.S_IMODE(path.stat().st_mode)


def certificate(path) -> x509.Certificate:
    return x509.load_pem_x509_certificate(path.read_bytes())


def common_name(cert: x509.Certificate) -> str:
    return cert.subject.get_attributes_for_oid(NameOID.COMMON_NAME)[0].value


def test_secrets_are_private_and_certificates_readable(profile):
    private = [profile / "ca" / "ca.key"]
    for host in ("robot", "192.168.1.10"):
        private += [profile / host / name for name in ("router.key", "router-link.key", "users.txt", "router.json5")]
    for role in ROLES:
        private += [profile / role / name for name in (f"{role}.key", "password", "client.json5")]
    assert {path.name: mode(path) for path in private} == {path.name: 0o600 for path in private}
    assert mode(profile / "ca" / "ca.pem") == 0o644 and mode(profile / "robot" / "router.pem") == 0o644


def test_router_certificates_name_the_host_and_localhost(profile, tmp_path):
    authority = certificate(profile / "ca" / "ca.pem")
    router = certificate(profile / "robot" / "router.pem")
    router.verify_directly_issued_by(authority)
    names = router.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
    assert names.get_values_for_type(x509.DNSName) == ["robot", "localhost"]
    assert names.get_values_for_type(x509.IPAddress) == [ipaddress.ip_address("127.0.0.1")]
    by_address = certificate(profile / "192.168.1.10" / "router.pem")
    addresses = by_address.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
    assert ipaddress.ip_address("192.168.1.10") in addresses.get_values_for_type(x509.IPAddress)
    # It listens with router.pem (a server's only) and joins other routers with router-link.pem
    # (a client's only, no names): the access control tells the two apart.
    usages = router.extensions.get_extension_for_class(x509.ExtendedKeyUsage).value
    assert list(usages) == [ExtendedKeyUsageOID.SERVER_AUTH]
    link = certificate(profile / "robot" / "router-link.pem")
    link.verify_directly_issued_by(authority)
    assert common_name(link) == "balltrack router link robot"
    assert list(link.extensions.get_extension_for_class(x509.ExtendedKeyUsage).value) == [ExtendedKeyUsageOID.CLIENT_AUTH]
    with pytest.raises(x509.ExtensionNotFound):
        link.extensions.get_extension_for_class(x509.SubjectAlternativeName)

    init_profile(tmp_path / "remote", ["robot"], local=False)
    remote = certificate(tmp_path / "remote" / "robot" / "router.pem")
    assert remote.extensions.get_extension_for_class(x509.SubjectAlternativeName).value \
        .get_values_for_type(x509.DNSName) == ["robot"]


def test_each_role_has_a_certificate_a_password_and_a_users_entry(profile):
    authority = certificate(profile / "ca" / "ca.pem")
    users = dict(line.split(":", 1) for line in (profile / "robot" / "users.txt").read_text().splitlines())
    # (the other host's router joins this one; this one's own user is in no users.txt of its own)
    assert set(users) == set(ROLES) | {"router-192.168.1.10"}
    passwords = set()
    for role in ROLES:
        cert = certificate(profile / role / f"{role}.pem")
        cert.verify_directly_issued_by(authority)
        assert common_name(cert) == f"balltrack {role}"
        password = (profile / role / "password").read_text().strip()
        assert users[role] == password and len(password) >= 24
        passwords.add(password)
        config = load_config_file(profile / role / "client.json5")
        assert config.get_json("mode") == '"client"'
        assert config.get_json("transport/auth/usrpwd/user") == f'"{role}"'
        assert config.get_json("transport/link/tls/enable_mtls") == "true"
        # File names resolve next to the config, wherever the folder was copied.
        assert config.get_json("transport/link/tls/connect_certificate") == f'"{profile.resolve() / role / (role + ".pem")}"'
    assert len(passwords) == len(ROLES)
    router = load_config_file(profile / "robot" / "router.json5")
    assert router.get_json("transport/auth/usrpwd/dictionary_file") == f'"{profile.resolve() / "robot" / "users.txt"}"'
    assert router.get_json("listen/endpoints") == '["tls/0.0.0.0:7447"]'
    assert router.get_json("access_control/default_permission") == '"deny"'
    assert router.get_json("transport/auth/usrpwd/user") == '"router-robot"'
    other = dict(line.split(":", 1) for line in (profile / "192.168.1.10" / "users.txt").read_text().splitlines())
    assert other["router-robot"] == json.loads(router.get_json("transport/auth/usrpwd/password"))
    assert other["router-robot"] != users["router-192.168.1.10"] and "router-192.168.1.10" not in other
    assert isinstance(zenoh.Config.from_file(str(profile / "robot" / "router.json5")), zenoh.Config)


def test_a_second_init_refuses_without_force(profile, capsys):
    before = (profile / "robot" / "router.key").read_bytes()
    assert main(["secure", "init", str(profile), "--hosts", "robot"]) == 2
    error = capsys.readouterr().err
    assert error.count("\n") == 1 and "--force" in error
    assert (profile / "robot" / "router.key").read_bytes() == before


def test_force_replaces_every_key(tmp_path, capsys):
    assert main(["secure", "init", str(tmp_path / "p"), "--hosts", "a,b"]) == 0
    old = (tmp_path / "p" / "a" / "router.key").read_bytes()
    assert main(["secure", "init", str(tmp_path / "p"), "--hosts", "a", "--force"]) == 0
    assert (tmp_path / "p" / "a" / "router.key").read_bytes() != old
    assert not (tmp_path / "p" / "b").exists()


@pytest.mark.parametrize("hosts", ["", "detector", "a,a", "bad host", "ca"])
def test_bad_host_lists_are_one_line_errors(hosts, tmp_path, capsys):
    with pytest.raises(ProfileError):
        parse_hosts(hosts)
    assert main(["secure", "init", str(tmp_path / "p"), "--hosts", hosts]) == 2
    assert capsys.readouterr().err.count("\n") == 1
    assert not (tmp_path / "p").exists()


def roles_that(kind: str, key: str) -> set[str]:
    return {role for role in ROLES if key in getattr(permissions(role), kind)}


def test_who_may_move_the_robot_and_publish_frames():
    assert roles_that("puts", key_table.CMD_VEL) == {"follower", "operator"}
    assert roles_that("puts", key_table.IMAGE_RAW) == {"simulator", "camera", "ros2_bridge"}
    assert roles_that("answers", key_table.SIM_CONTROL) == {"simulator"}
    assert roles_that("queries", key_table.SIM_CONTROL) == {"operator"}


def test_each_service_owns_its_stats_config_and_token_only():
    for role in ROLES:
        granted = permissions(role)
        if role in SERVICES:
            assert f"{role}/stats" in granted.puts and f"{role}/config" in granted.answers
            assert granted.tokens == (f"alive/{role}",)
            assert not any(key.endswith("/stats") and key != f"{role}/stats" for key in granted.puts)
        else:
            assert granted.tokens == () and granted.answers == ()
    assert set(SERVICES) <= set(ROLES)
    viewer = permissions("viewer")
    assert viewer.puts == () and viewer.queries == ("@/**",) and viewer.subscribes == ("**",)


def test_access_control_subjects_need_both_certificate_and_user(tmp_path):
    acl = access_control("robot1", ["a", "b"])
    rules = {rule["id"]: rule for rule in acl["rules"]}
    assert acl["default_permission"] == "deny"
    assert all(rule["permission"] == "allow" for rule in acl["rules"])
    subjects = {subject["id"]: subject for subject in acl["subjects"]}
    assert subjects["locator"] == {"id": "locator", "cert_common_names": ["balltrack locator"],
                                   "usernames": ["locator"]}
    # Another host's router: by its link certificate AND its own router user when it dials in,
    # by its listening (server-only) certificate when dialled; never by a certificate name alone
    # that a client could present.
    assert subjects["router a joining"] == {"id": "router a joining", "cert_common_names": ["balltrack router link a"],
                                            "usernames": ["router-a"]}
    assert subjects["router b joined"] == {"id": "router b joined", "cert_common_names": ["balltrack router b"]}
    (router_policy,) = [policy for policy in acl["policies"] if policy["id"] == "router"]
    assert router_policy["subjects"] == ["router a joining", "router a joined", "router b joining", "router b joined"]
    assert rules["follower put"]["key_exprs"] == ["robot1/cmd_vel", "robot1/follower/stats"]
    assert rules["viewer query"]["key_exprs"] == ["@/**"]  # the admin space has no namespace
    for policy in acl["policies"]:
        assert all(rules[rule]["id"].split()[0] == policy["subjects"][0].split()[0] for rule in policy["rules"])
    assert not any(subject["id"].startswith("router") for subject in access_control("", [])["subjects"])


def users(path) -> dict[str, str]:
    return dict(line.split(":", 1) for line in path.read_text().splitlines())


def test_renew_replaces_one_roles_or_hosts_credentials_and_keeps_the_rest(tmp_path, capsys):
    directory = tmp_path / "p"
    init_profile(directory, ["a", "b"])
    files = {path: path.read_bytes() for path in directory.rglob("*") if path.is_file()}
    assert main(["secure", "renew", str(directory), "operator,b"]) == 0
    changed = {path.relative_to(directory).as_posix() for path, data in files.items() if path.read_bytes() != data}
    assert changed == {"operator/operator.pem", "operator/operator.key", "operator/password", "operator/client.json5",
                       "a/users.txt", "b/users.txt", "b/router.pem", "b/router.key", "b/router-link.pem",
                       "b/router-link.key", "b/router.json5"}
    operator = (directory / "operator" / "password").read_text().strip()
    assert users(directory / "a" / "users.txt")["operator"] == users(directory / "b" / "users.txt")["operator"] == operator
    config = load_config_file(directory / "operator" / "client.json5")
    assert config.get_json("transport/auth/usrpwd/password") == json.dumps(operator)
    router = load_config_file(directory / "b" / "router.json5")
    assert users(directory / "a" / "users.txt")["router-b"] == json.loads(router.get_json("transport/auth/usrpwd/password"))
    authority = certificate(directory / "ca" / "ca.pem")
    certificate(directory / "operator" / "operator.pem").verify_directly_issued_by(authority)
    listening = certificate(directory / "b" / "router.pem")
    assert listening.extensions.get_extension_for_class(x509.SubjectAlternativeName).value \
        .get_values_for_type(x509.DNSName) == ["b", "localhost"]
    assert "copy these to their hosts and restart the routers" in capsys.readouterr().out
    assert mode(directory / "operator" / "password") == mode(directory / "a" / "users.txt") == 0o600


@pytest.mark.parametrize("names, reason", [
    ("nobody", "'nobody' is neither a role"), ("", "name a role or a host"), ("ca", "'ca' is neither a role")])
def test_renew_refuses_what_the_profile_lacks_in_one_line(names, reason, tmp_path, capsys):
    init_profile(tmp_path / "p", ["a"])
    before = (tmp_path / "p" / "a" / "users.txt").read_text()
    assert main(["secure", "renew", str(tmp_path / "p"), names]) == 2
    error = capsys.readouterr().err
    assert error.count("\n") == 1 and reason in error, error
    (tmp_path / "p" / "ca" / "ca.key").unlink()
    assert main(["secure", "renew", str(tmp_path / "p"), "viewer"]) == 2
    assert "ca.key: renew on the machine that keeps the profile's CA" in capsys.readouterr().err
    assert (tmp_path / "p" / "a" / "users.txt").read_text() == before


def test_renew_refuses_a_host_of_a_profile_without_link_certificates(tmp_path, capsys):
    # (an earlier profile: its router dials with router.pem, which a renewed one could not)
    init_profile(tmp_path / "p", ["a"])
    (tmp_path / "p" / "a" / "router-link.pem").unlink()
    assert main(["secure", "renew", str(tmp_path / "p"), "a"]) == 2
    assert "no router-link.pem" in capsys.readouterr().err


# -- a fleet (--robots) -----------------------------------------------------------------------
ROBOTS = ["robot1", "robot2"]


def test_a_fleets_robot_roles_reach_only_their_own_namespace():
    acl = access_control("", [], ROBOTS)
    rules = {rule["id"]: rule for rule in acl["rules"]}
    subjects = {subject["id"]: subject for subject in acl["subjects"]}
    robot_roles = [f"{role}@{robot}" for robot in ROBOTS for role in ROBOT_ROLES]
    assert list(subjects) == [*FLEET_ROLES, *robot_roles]
    assert set(FLEET_ROLES) == {"detector", "locator", "follower", "simulator", "viewer", "operator"}
    # (no fleet-wide camera or bridge: one runs per robot; a robot's viewer watches it alone)
    assert set(ROBOT_ROLES) == {*SERVICES, "viewer"}
    assert subjects["follower@robot1"] == {"id": "follower@robot1", "cert_common_names": ["balltrack follower@robot1"],
                                           "usernames": ["follower@robot1"]}
    for policy in acl["policies"]:
        name = policy["subjects"][0]
        assert policy["subjects"] == [name] and name in subjects
        keys = [key for rule in policy["rules"] for key in rules[rule]["key_exprs"]
                if not rule.endswith("put matching")]  # (that someone listens, never what is said)
        if "@" in name:
            robot = name.split("@")[1]
            assert all(key.startswith(f"{robot}/") for key in keys), (name, keys)
        else:  # fleet-wide: every robot's keys, the admin space, every robot's tokens
            own = ["simulator/stats", "simulator/config", "alive/simulator"] if name == "simulator" else []
            assert all(key.startswith(("robot1/", "robot2/", "@/", "**/alive/")) or key in own for key in keys), (name, keys)
            assert any(key.startswith("robot1/") for key in keys) and any(key.startswith("robot2/") for key in keys)
    assert rules["follower@robot1 put"]["key_exprs"] == ["robot1/cmd_vel", "robot1/follower/stats"]
    assert rules["detector@robot1 subscribe"]["key_exprs"] == ["robot1/camera/image_raw"]
    assert rules["simulator@robot2 answer"]["key_exprs"] == ["robot2/camera/camera_info", "robot2/sim/control",
                                                            "robot2/simulator/config"]
    assert rules["simulator@robot2 watch"]["key_exprs"] == ["robot2/alive/*"]
    # A simulator holding both robots: each robot's keys, and outside them only its own.
    assert rules["simulator put"]["key_exprs"][:2] == ["robot1/camera/image_raw", "robot1/camera/camera_info"]
    assert [rules[f"simulator own {kind}"]["key_exprs"] for kind in ("put", "answer", "token")] == [
        ["simulator/stats"], ["simulator/config"], ["alive/simulator"]]
    assert rules["operator put"]["key_exprs"] == ["robot1/cmd_vel", "robot2/cmd_vel"]
    assert rules["viewer subscribe"]["key_exprs"] == ["robot1/**", "robot2/**"]
    assert rules["viewer watch"]["key_exprs"] == rules["operator watch tokens"]["key_exprs"] == ["**/alive/*"]
    assert rules["locator token"]["key_exprs"] == ["robot1/alive/locator", "robot2/alive/locator"]
    # A robot's viewer: its robot's keys and tokens, not the admin space (every robot's keys).
    assert [rule for rule in rules if rule.startswith("viewer@robot1")] == [
        "viewer@robot1 subscribe", "viewer@robot1 subscribe delivery", "viewer@robot1 watch",
        "viewer@robot1 watch tokens"]
    assert rules["viewer@robot1 watch"]["key_exprs"] == ["robot1/alive/*"]
    # Without --robots, the rules as they were.
    assert access_control("ns")["subjects"] == [{"id": role, "cert_common_names": [f"balltrack {role}"],
                                                 "usernames": [role]} for role in ROLES]


def test_a_fleet_profile_writes_each_robots_credentials(tmp_path):
    directory = tmp_path / "fleet"
    init_profile(directory, ["a"], robots=ROBOTS)
    users = dict(line.split(":", 1) for line in (directory / "a" / "users.txt").read_text().splitlines())
    assert set(users) == {*FLEET_ROLES, *(f"{role}@{robot}" for robot in ROBOTS for role in ROBOT_ROLES)}
    assert not (directory / "camera").exists() and (directory / "simulator" / "client.json5").is_file()
    folder = directory / "robots" / "robot1" / "follower"
    assert common_name(certificate(folder / "follower.pem")) == "balltrack follower@robot1"
    assert users["follower@robot1"] == (folder / "password").read_text().strip() != users["follower"]
    config = load_config_file(folder / "client.json5")
    assert config.get_json("transport/auth/usrpwd/user") == '"follower@robot1"'
    certificate_path = config.get_json("transport/link/tls/connect_certificate")
    assert certificate_path == json.dumps(str(folder.resolve() / "follower.pem"))
    assert mode(folder / "follower.key") == mode(folder / "password") == mode(folder / "client.json5") == 0o600
    router = "".join(line for line in (directory / "a" / "router.json5").read_text().splitlines(True)
                     if not line.startswith("//"))  # (its header)
    assert json.loads(router)["access_control"] == access_control("", [], ROBOTS)
    # --force without --robots: no robot's credentials left beside the new profile
    init_profile(directory, ["a"], force=True)
    assert not (directory / "robots").exists() and (directory / "simulator" / "client.json5").is_file()


@pytest.mark.parametrize("robots, reason", [
    ("", "empty name"), ("robot1,robot1", "'robot1' is listed twice"), ("robot1,,robot2", "empty name"),
    ("r*", "may not contain"), ("a:b", "a robot's name is"), ("fleet/robot1", "a robot's name is")])
def test_bad_robot_lists_are_one_line_errors(robots, reason, tmp_path, capsys):
    with pytest.raises(ProfileError, match=reason):
        parse_robots(robots)
    assert main(["secure", "init", str(tmp_path / "p"), "--hosts", "a", "--robots", robots]) == 2
    error = capsys.readouterr().err
    assert error.count("\n") == 1 and reason in error, error
    assert not (tmp_path / "p").exists()


@pytest.mark.parametrize("arguments, reason", [
    (["--hosts", "a", "--namespace", "site"], "no --namespace with it"),
    (["--hosts", "robots"], "'robots' is the folder of the robots' credentials")])
def test_robots_with_a_namespace_or_a_host_named_robots_are_refused(arguments, reason, tmp_path, capsys):
    assert main(["secure", "init", str(tmp_path / "p"), *arguments, "--robots", "robot1"]) == 2
    error = capsys.readouterr().err
    assert error.count("\n") == 1 and reason in error, error


def test_a_process_serving_one_robot_uses_its_credentials(tmp_path):
    directory = tmp_path / "fleet"
    init_profile(directory, ["a"], robots=ROBOTS)
    assert secure_client_path(directory, "follower", "robot1") == directory / "robots/robot1/follower/client.json5"
    # a robot the profile lacks, a fleet-wide command role, no robot: the fleet-wide credentials
    for role, namespace in (("follower", "robot3"), ("operator", "robot1"), ("follower", ""), ("follower", "..")):
        assert secure_client_path(directory, role, namespace) == directory / role / "client.json5"
    with pytest.raises(ValueError, match="no .*robots/robot1/simulator/client.json5 nor .*simulator/client.json5"):
        secure_client_path(tmp_path / "elsewhere", "simulator", "robot1")
    served = lambda **options: served_namespace(argparse.Namespace(**options))  # noqa: E731
    assert served(namespace="/robot1/") == served(namespaces=["robot1"], namespace="") == "robot1"
    assert served(namespaces=["robot1", "robot2"], namespace="") == ""
    assert served(namespaces=[], discover_robots=True, namespace="") == ""
    assert served(namespace=None) == ""  # (play's, unless given)


def test_renew_replaces_one_robots_role(tmp_path, capsys):
    directory = tmp_path / "fleet"
    init_profile(directory, ["a"], robots=ROBOTS)
    files = {path: path.read_bytes() for path in directory.rglob("*") if path.is_file()}
    assert main(["secure", "renew", str(directory), "follower@robot1"]) == 0
    changed = {path.relative_to(directory).as_posix() for path, data in files.items() if path.read_bytes() != data}
    assert changed == {f"robots/robot1/follower/{name}" for name in ("follower.pem", "follower.key", "password",
                                                                      "client.json5")} | {"a/users.txt"}
    password = (directory / "robots" / "robot1" / "follower" / "password").read_text().strip()
    assert users(directory / "a" / "users.txt")["follower@robot1"] == password
    capsys.readouterr()
    for name in ("follower@robot3", "operator@robot1", "follower@"):
        assert main(["secure", "renew", str(directory), name]) == 2
        assert capsys.readouterr().err.count("\n") == 1
