"""The secure profile over a real router: who may join, and what each role may do.

A profile is generated into tmp_path (host ``testhost``; its router certificate names
localhost and 127.0.0.1), the router listens on ``tls/127.0.0.1:PORT`` (a free port), and
clients dial ``tls/localhost:PORT`` as their role. Zenoh refuses a client it cannot
authenticate while opening the session: ``zenoh.open`` keeps retrying the link until its
connect timeout, then raises "Unable to connect to any of [...]" (our SessionOpenError). A
client that authenticates but matches no role (a password under another role's certificate)
opens, and every message to or from it is dropped. Frames are small (160x120) to keep the CPU low.
Tests marked FLEET run over a fleet's profile (``--robots robot1,robot2``).
"""

import json
import shutil
import subprocess
import sys
import time

import pytest
import zenoh

from balltrack.common.messages import encode, header
from balltrack.common.network import free_port
from balltrack.common.session import load_config_file, open_session, secure_client_path
from balltrack.common.status import liveliness_keys, services_by_namespace
from balltrack.deploy.secure import init_profile, permissions
from balltrack.services.simulator.control import send_command
from tests.harness import (REPO, Collector, Liveliness, Process, process_environment, put_until, start_service,
                           wait_matched, wait_until)

SMALL = ("--set", "width=160", "--set", "height=120")
# Opening a refused session waits this long (Zenoh retries the link until then).
REFUSED_OPEN_TIMEOUT = 3.0


@pytest.fixture(scope="module")
def profile(tmp_path_factory, request):
    """A one-host profile; a fleet's, of the robots given as the indirect parameter (``FLEET``)."""
    directory = tmp_path_factory.mktemp("profile")
    init_profile(directory, ["testhost"], robots=getattr(request, "param", []))
    return directory


@pytest.fixture
def secure_router(profile, tmp_path):
    port = free_port()
    process = Process([sys.executable, "-m", "balltrack", "router", "--secure", str(profile),
                       "--listen", f"tls/127.0.0.1:{port}"], tmp_path / "router.log")
    process.wait_for_output("listening on", 20)
    yield port
    assert process.stop() == 0, process.output()


@pytest.fixture
def as_role(profile, secure_router):
    """``as_role("locator")``: a session opened with that role's client config;
    ``as_role("follower", "robot1")``: with the robot's own, in a fleet's profile."""
    opened = []

    def open_as(role: str, robot: str = ""):
        session = open_session([f"tls/localhost:{secure_router}"], str(secure_client_path(profile, role, robot)),
                               open_timeout=10)
        opened.append(session)
        return session

    yield open_as
    for session in opened:
        session.close()


@pytest.fixture
def simulator(profile, secure_router, as_role, tmp_path):
    """The simulator as its role, realtime; the robot moves only when commanded."""
    process = Process([sys.executable, "-m", "balltrack.services.simulator", "--secure", str(profile),
                       "--connect", f"tls/localhost:{secure_router}", *SMALL, "--set", "pacing=realtime",
                       "--set", "cmd_timeout=0.5"], tmp_path / "simulator.log")
    Liveliness(as_role("operator")).wait("simulator", timeout=40)
    yield process
    assert process.stop() == 0, process.output()


def role_config(profile, role: str, port: int, **changes):
    config = load_config_file(secure_client_path(profile, role))
    config.insert_json5("connect/endpoints", json.dumps([f"tls/localhost:{port}"]))
    config.insert_json5("connect/timeout_ms", str(int(REFUSED_OPEN_TIMEOUT * 1000)))
    for setting, value in changes.items():
        config.insert_json5(setting.replace(".", "/"), json.dumps(value))
    return config


def assert_refused(config):
    with pytest.raises(zenoh.ZError, match="Unable to connect to any of"):
        zenoh.open(config)


def twist(linear: float, angular: float) -> bytes:
    return encode("Twist", {"header": header(0, 0, "base_link"), "linear": [linear, 0.0, 0.0],
                            "angular": [0.0, 0.0, angular]})


def put_until_seen(session, key: str, payload: bytes, collector: Collector, timeout: float = 10) -> None:
    """Put until ``collector`` has it: a new subscription takes a moment to reach publishers,
    and until then Zenoh drops puts at the writer."""
    put_until(lambda _: session.put(key, payload), collector,
              lambda messages: any(m["payload"] == payload for m in messages), timeout, 0.2,
              f"{payload!r} on {key} at the subscriber")


def moved(before: dict, after: dict) -> float:
    return (abs(after["robot"]["x"] - before["robot"]["x"]) + abs(after["robot"]["y"] - before["robot"]["y"])
            + abs(after["robot"]["yaw"] - before["robot"]["yaw"]))


def command_for_frames(session, truths: Collector, frames: int) -> tuple[dict, dict]:
    """Put cmd_vel every third frame for ``frames`` frames; (ground truth before, after)."""
    before = truths.wait_for(lambda messages: messages and messages[-1], 20, "a ground truth")
    seq = before["header"]["seq"]
    while seq < before["header"]["seq"] + frames:
        session.put("cmd_vel", twist(0.4, 0.8))
        seq = truths.wait_for(lambda messages, target=seq + 3: next(
            (m for m in messages if m["header"]["seq"] >= target), None), 20, "3 frames more")["header"]["seq"]
    return before, truths.messages[-1]


# -- who may join -----------------------------------------------------------------------------
def test_a_client_of_the_profile_joins(profile, secure_router):
    session = zenoh.open(role_config(profile, "locator", secure_router))
    assert len(session.info.routers_zid()) == 1
    session.close()


def test_without_a_certificate_the_session_is_refused(profile, secure_router):
    # The right user and password, but no client certificate (mTLS off on this side).
    assert_refused(role_config(profile, "locator", secure_router, **{"transport.link.tls.enable_mtls": False}))


def test_a_wrong_password_is_refused(profile, secure_router):
    assert_refused(role_config(profile, "locator", secure_router,
                               **{"transport.auth.usrpwd.password": "not-the-password"}))


def test_plain_tcp_is_refused(profile, secure_router):
    # The router listens for TLS only: a plain TCP client on its port never completes a session.
    config = role_config(profile, "locator", secure_router, **{"transport.link.protocols": ["tcp", "tls"]})
    config.insert_json5("connect/endpoints", json.dumps([f"tcp/127.0.0.1:{secure_router}"]))
    assert_refused(config)


def test_the_router_says_the_names_clients_may_dial_it_at(profile, tmp_path):
    # (the names its certificate holds: an interface's address it lacks would be refused)
    port = free_port()
    process = Process([sys.executable, "-m", "balltrack", "router", "--secure", str(profile),
                       "--listen", f"tls/0.0.0.0:{port}"], tmp_path / "router.log")
    try:
        process.wait_for_output("listening on", 20)
    finally:
        assert process.stop() == 0, process.output()
    assert (f"listening on tls/0.0.0.0:{port} (reached at tls/testhost:{port}, tls/localhost:{port}, "
            f"tls/127.0.0.1:{port}: the names its certificate holds)") in process.output()


def test_a_router_address_its_certificate_does_not_name_is_refused(profile, secure_router):
    config = role_config(profile, "locator", secure_router)
    config.insert_json5("connect/endpoints", json.dumps([f"tls/127.0.0.2:{secure_router}"]))
    assert_refused(config)


def test_service_without_credentials_exits_with_one_line(profile, secure_router, tmp_path, monkeypatch):
    # A plain `--connect tcp/...` service, as before the profile: it cannot join.
    monkeypatch.setenv("BALLTRACK_OPEN_TIMEOUT", str(REFUSED_OPEN_TIMEOUT))
    process = Process([sys.executable, "-m", "balltrack.services.detector", "--connect",
                       f"tcp/127.0.0.1:{secure_router}"], tmp_path / "plain.log")
    process.popen.wait(60)
    assert process.popen.returncode == 1
    assert "cannot reach a Zenoh router" in process.output()


def test_a_password_under_another_roles_certificate_matches_no_role(profile, secure_router, as_role):
    password = (profile / "detector" / "password").read_text().strip()
    mixed = zenoh.open(role_config(profile, "locator", secure_router, **{
        "transport.auth.usrpwd.user": "detector", "transport.auth.usrpwd.password": password}))
    operator = as_role("operator")
    detector = as_role("detector")
    seen = Collector(operator, "detected_ball", None)
    mixed_frames = Collector(mixed, "camera/image_raw", None)
    simulator_session = as_role("simulator")
    frames = Collector(operator, "camera/image_raw", None)
    put_until_seen(detector, "detected_ball", b"from the detector", seen)
    mixed.put("detected_ball", b"from the mixed identity")
    put_until_seen(simulator_session, "camera/image_raw", b"a frame", frames)
    put_until_seen(detector, "detected_ball", b"from the detector, later", seen)
    assert {m["payload"] for m in seen.messages} == {b"from the detector", b"from the detector, later"}
    assert mixed_frames.messages == []
    mixed.close()


# -- what each role may do ----------------------------------------------------------------------
def test_only_the_follower_role_moves_the_robot(simulator, as_role):
    truths = Collector(as_role("viewer"), "sim/ground_truth", "GroundTruth")
    commands = Collector(as_role("operator"), "cmd_vel", None)
    for role in ("locator", "viewer", "detector"):
        before, after = command_for_frames(as_role(role), truths, 30)
        assert moved(before, after) == 0.0, f"{role}'s cmd_vel moved the robot"
    assert commands.messages == []  # nor did any of them reach another subscriber
    before, after = command_for_frames(as_role("follower"), truths, 30)
    assert moved(before, after) > 0.1
    assert commands.messages


def test_viewer_watches_but_its_puts_and_queries_are_dropped(simulator, as_role):
    viewer, operator, detector = as_role("viewer"), as_role("operator"), as_role("detector")
    frames = Collector(viewer, "camera/image_raw", "Image")
    frames.wait_count(3, 20)
    balls = Collector(operator, "detected_ball", None)
    put_until_seen(detector, "detected_ball", b"from the detector", balls)
    viewer.put("detected_ball", b"from the viewer")
    put_until_seen(detector, "detected_ball", b"from the detector, later", balls)
    assert {m["payload"] for m in balls.messages} == {b"from the detector", b"from the detector, later"}
    # sim/control: the viewer gets no answer, the operator does.
    assert not send_command(viewer, {"op": "reset"}, timeout=2)["ok"]
    assert send_command(operator, {"op": "reset"}, timeout=5)["ok"]


def test_a_role_declares_only_its_own_liveliness_token(as_role):
    locator, operator = as_role("locator"), as_role("operator")
    tokens = Liveliness(operator)
    forged = locator.liveliness().declare_token("alive/follower")
    own = locator.liveliness().declare_token("alive/locator")
    tokens.wait("locator", timeout=10)
    assert liveliness_keys(operator, "alive/*", timeout=3) == {"alive/locator"}
    assert "follower" not in tokens.alive
    forged.undeclare()
    own.undeclare()


def test_only_the_simulator_may_answer_sim_control(as_role):
    operator = as_role("operator")
    for role, allowed in (("simulator", True), ("locator", False), ("follower", False)):
        answering = as_role(role).declare_queryable("sim/control", lambda query: query.reply(
            "sim/control", encode("SimReply", {"ok": True})))
        if allowed:  # the declaration reaches the router some time after it returns
            deadline = time.monotonic() + 10
            while not send_command(operator, {"op": "reset"}, timeout=1)["ok"]:
                assert time.monotonic() < deadline, f"{role}: never answered in 10 s"
        else:  # denied at the router: no answer in 2 s, far longer than an allowed one needed
            assert not send_command(operator, {"op": "reset"}, timeout=2)["ok"], role
        answering.undeclare()


def test_the_secure_system_runs_alive_with_stats_and_data(profile, tmp_path):
    """Every core service under its role: alive, publishing stats, the pipeline flowing to cmd_vel."""
    from balltrack.deploy.launcher import SERVICES as CORE, start_system

    settings = {"simulator": ["width=320", "height=240", "pacing=realtime"], "follower": ["use_sim_time=true"]}
    with start_system(tmp_path / "run", CORE, settings, secure=profile, output=None) as system:
        assert system.endpoint.startswith("tls/127.0.0.1:")
        session = open_session([system.endpoint], str(secure_client_path(profile, "viewer")), open_timeout=10)
        stats = Collector(session, "*/stats", "Stats")
        balls = Collector(session, "detected_ball_3d", "Ball3D")
        commands = Collector(session, "cmd_vel", "Twist")
        stats.wait_for(lambda messages: {m["service"] for m in messages} >= set(CORE), 30, "stats of every service")
        balls.wait_count(5, 30)
        commands.wait_count(5, 30)
        assert all(m["rejected"] == 0 for m in stats.messages)
        session.close()
        assert system.stop() == 0


def test_roles_grant_what_the_services_declare(tmp_path):
    """The ROLES table against the services' real declarations, read from a plain (no access
    control) router's admin space: each service declares exactly the subscriptions and
    queryables, publishers and tokens its role grants."""
    from balltrack.deploy.launcher import SERVICES as CORE, start_system

    settings = {"simulator": ["width=160", "height=120", "pacing=lockstep"], "follower": ["use_sim_time=true"]}
    with start_system(tmp_path / "run", CORE, settings, output=None) as system:
        session = open_session([system.endpoint], open_timeout=10)
        declared: dict[str, dict[str, set[str]]] = {}
        zids: dict[str, set[str]] = {}
        for reply in session.get("@/*/router/**", timeout=5):
            if reply.ok is None:
                continue
            parts = str(reply.ok.key_expr).split("/")
            if len(parts) < 5 or parts[3] not in ("publisher", "subscriber", "queryable", "token"):
                continue
            holders = json.loads(reply.ok.payload.to_bytes())
            key = "/".join(parts[4:])
            # (the launcher's services join a plain router as its peers, see common/session.py)
            for zid in holders.get("clients", []) + holders.get("peers", []):
                declared.setdefault(zid, {}).setdefault(parts[3], set()).add(key)
                if parts[3] == "token" and key.startswith("alive/"):
                    zids.setdefault(key.split("/", 1)[1], set()).add(zid)
        session.close()
    assert set(zids) == set(CORE)
    # Granted for a setting switched live, not declared with the defaults used here: the
    # follower's other detection key (keep_target=false follows detected_ball).
    switched = {"follower": {"detected_ball"}}
    for service in CORE:
        (zid,) = zids[service]
        granted = permissions(service)
        entities = declared[zid]
        assert (entities.get("subscriber", set()) == set(granted.subscribes) - switched.get(service, set())), \
            (service, entities)
        assert entities.get("queryable", set()) == set(granted.answers), (service, entities)
        assert entities.get("token", set()) == set(granted.tokens), (service, entities)
        assert entities.get("publisher", set()) == set(granted.puts), (service, entities)


@pytest.fixture
def two_hosts(tmp_path):
    """A profile of two hosts and a router per host (both on this machine), hostb's joining
    hosta's: (profile, hosta's port, hostb's port)."""
    directory = tmp_path / "profile"
    init_profile(directory, ["hosta", "hostb"])
    first, second = free_port(), free_port()
    routers = [Process([sys.executable, "-m", "balltrack", "router", "--secure", str(directory), "--host", "hosta",
                        "--listen", f"tls/127.0.0.1:{first}"], tmp_path / "a.log")]
    routers[0].wait_for_output("listening on", 20)
    routers.append(Process([sys.executable, "-m", "balltrack", "router", "--secure", str(directory), "--host", "hostb",
                            "--listen", f"tls/127.0.0.1:{second}", "--connect", f"tls/localhost:{first}"],
                           tmp_path / "b.log"))
    routers[1].wait_for_output("listening on", 20)
    yield directory, first, second
    assert [router.stop() for router in routers] == [0, 0], [router.output() for router in routers]


def test_two_hosts_routers_join_and_keep_the_rules(two_hosts):
    """A follower on one host moves commands to a simulator on the other, a locator's do not cross."""
    directory, first, second = two_hosts
    as_role = lambda role, port: open_session([f"tls/localhost:{port}"],  # noqa: E731
                                              str(secure_client_path(directory, role)), open_timeout=10)
    simulator, follower, locator = as_role("simulator", first), as_role("follower", second), as_role("locator", second)
    commands = Collector(simulator, "cmd_vel", None)
    put_until_seen(follower, "cmd_vel", b"from the follower", commands, timeout=20)
    locator.put("cmd_vel", b"from the locator")
    put_until_seen(follower, "cmd_vel", b"from the follower, later", commands)
    assert b"from the locator" not in {message["payload"] for message in commands.messages}
    for session in (simulator, follower, locator):
        session.close()


def test_a_routers_folder_does_not_make_a_client_of_another_hosts_router(two_hosts):
    """A client holding hosta's router folder (its certificates and keys, the router password of
    its router.json5, the role passwords of its users.txt) joins hostb's router: it is refused,
    or it may neither put cmd_vel nor read. (It used to be let in as a router: put cmd_vel, read
    everything.) Left out: the folder's own identity, its link certificate with its own router
    password, which is router hosta itself."""
    directory, first, second = two_hosts
    folder = directory / "hosta"
    own = load_config_file(folder / "router.json5")
    router_user = json.loads(own.get_json("transport/auth/usrpwd/user"))
    users = dict(line.split(":", 1) for line in (folder / "users.txt").read_text().splitlines())
    # Its own router's password, a role's, and hostb's router's (hosta's users.txt lets hostb join it)
    passwords = {router_user: json.loads(own.get_json("transport/auth/usrpwd/password")), "viewer": users["viewer"],
                 "router-hostb": users["router-hostb"]}
    simulator = open_session([f"tls/localhost:{first}"], str(secure_client_path(directory, "simulator")), open_timeout=10)
    follower = open_session([f"tls/localhost:{second}"], str(secure_client_path(directory, "follower")), open_timeout=10)
    opened = [simulator, follower]
    try:
        commands = Collector(simulator, "cmd_vel", None)
        put_until_seen(follower, "cmd_vel", b"from the follower", commands, timeout=20)
        tried = []
        for certificate in sorted(folder.glob("router*.pem")):
            for user, password in passwords.items():
                if certificate.name == "router-link.pem" and user == router_user:
                    continue
                tried.append((certificate.name, user))
                config = role_config(directory, "locator", second, **{
                    "transport.link.tls.connect_certificate": str(certificate),
                    "transport.link.tls.connect_private_key": str(certificate.with_suffix(".key")),
                    "transport.auth.usrpwd.user": user, "transport.auth.usrpwd.password": password})
                try:
                    opened.append(zenoh.open(config))
                except zenoh.ZError:
                    continue  # refused: it never joined
                seen = Collector(opened[-1], "**", None)
                payload = f"from {certificate.name} as {user}".encode()
                with pytest.raises(AssertionError, match="no .* in 2 s"):
                    put_until_seen(opened[-1], "cmd_vel", payload, commands, timeout=2)
                put_until_seen(follower, "cmd_vel", b"after " + payload, commands)
                # (its own puts come back to it within its session)
                assert [m for m in seen.messages if m["payload"] != payload] == [], (certificate.name, user)
        assert len(tried) == 5
    finally:
        for session in opened:
            session.close()


def test_a_renewed_roles_old_credentials_are_refused_and_the_others_still_join(tmp_path):
    from balltrack.cli import main

    directory = tmp_path / "profile"
    init_profile(directory, ["testhost"])
    shutil.copytree(directory / "operator", tmp_path / "old" / "operator")
    assert main(["secure", "renew", str(directory), "operator"]) == 0
    port = free_port()
    router = Process([sys.executable, "-m", "balltrack", "router", "--secure", str(directory),
                      "--listen", f"tls/127.0.0.1:{port}"], tmp_path / "router.log")
    try:
        router.wait_for_output("listening on", 20)
        assert_refused(role_config(tmp_path / "old", "operator", port))
        for role in ("operator", "locator"):  # the renewed one, one left as it was
            session = zenoh.open(role_config(directory, role, port))
            assert len(session.info.routers_zid()) == 1, role
            session.close()
    finally:
        assert router.stop() == 0, router.output()


# A command's client-side role check left out, as by a client of its own: what reaches the
# router is up to its access control alone.
WITHOUT_ROLE_CHECK = ("import sys\nfrom balltrack.cli import config, main, network, publish, recording\n"
                      "for module in (config, network, publish, recording):\n"
                      "    module.refused_for_role = lambda *arguments: False\n"
                      "sys.exit(main(sys.argv[1:]))")


def balltrack(port: int, profile, *arguments: str, role_check: bool = True) -> subprocess.CompletedProcess:
    """``balltrack ARGUMENTS --secure PROFILE`` against the router at ``port``."""
    command = [sys.executable, *(["-m", "balltrack"] if role_check else ["-c", WITHOUT_ROLE_CHECK])]
    return subprocess.run([*command, *arguments, "--secure", str(profile), "--connect", f"tls/localhost:{port}"],
                          capture_output=True, text=True, timeout=60, env=process_environment())


def recording(path, key: str, message_type: str, payload: bytes) -> None:
    from balltrack.common.recording import Recorder

    recorder = Recorder(path)
    recorder.write_payload(recorder.msgpack_channel(key, key, "", message_type), payload,
                           arrival_ns=1_700_000_000_000_000_000)
    recorder.close()


def test_commands_that_write_need_the_operator_role(profile, secure_router, tmp_path):
    # (they acted as operator unless told otherwise: drive the robot, set parameters)
    recording(tmp_path / "cmd_vel.mcap", "cmd_vel", "Twist", twist(0.1, 0.0))
    refused = {("pub", "cmd_vel", "{linear: [0, 0, 0], angular: [0, 0, 0]}"): "cmd_vel",
               ("sim", "reset"): "sim/control",
               ("config", "simulator", "pacing=lockstep"): "simulator/config",
               ("config", "simulator"): "simulator/config",
               ("play", str(tmp_path / "cmd_vel.mcap")): "cmd_vel"}
    for arguments, key in refused.items():
        finished = balltrack(secure_router, profile, *arguments, "--timeout", "2")
        assert (finished.returncode, finished.stderr) == (
            2, f"balltrack {arguments[0]}: {key} needs --role operator (this client is viewer)\n"), arguments
    # What no person's role may put: the roles that may.
    recording(tmp_path / "frames.mcap", "camera/image_raw", "Image", encode("Image", {
        "header": header(0, 0), "width": 1, "height": 1, "encoding": "rgb8", "data": b"\0\0\0"}))
    frames = balltrack(secure_router, profile, "play", str(tmp_path / "frames.mcap"), "--role", "operator")
    assert (frames.returncode, frames.stderr) == (
        2, "balltrack play: camera/image_raw needs --role simulator, camera or ros2_bridge (this client is "
           "operator)\n")


def test_a_viewers_cmd_vel_is_dropped_by_the_router_without_the_client_check(profile, secure_router, as_role):
    commands = Collector(as_role("simulator"), "cmd_vel", "Twist")

    def pub(linear: float, *role: str) -> subprocess.CompletedProcess:
        return balltrack(secure_router, profile, "pub", "cmd_vel", f"{{linear: [{linear}, 0, 0], angular: [0, 0, 0]}}",
                         "--rate", "20", "--count", "20", *role, role_check=False)

    viewer = pub(0.25)
    assert viewer.returncode == 0 and "published 20 Twist" in viewer.stderr, viewer.stderr
    operator = pub(0.5, "--role", "operator")
    assert operator.returncode == 0, operator.stderr
    commands.wait_for(lambda messages: any(m["linear"][0] == 0.5 for m in messages), 10, "the operator's cmd_vel")
    assert {m["linear"][0] for m in commands.messages} == {0.5}


def test_a_config_query_the_access_control_drops_says_it_may_be_that(profile, simulator, secure_router):
    # (it said only "no simulator answered", with the simulator alive and answering others)
    viewer = balltrack(secure_router, profile, "config", "simulator", "--timeout", "2", role_check=False)
    assert viewer.returncode == 1
    assert viewer.stderr == ("balltrack config: no simulator answered on simulator/config; or the access control "
                             "does not let role viewer ask it\n")
    operator = balltrack(secure_router, profile, "config", "simulator", "--role", "operator")
    assert operator.returncode == 0 and json.loads(operator.stdout)["pacing"] == "realtime", operator.stderr


# -- a fleet: each robot's roles confined to its namespace ------------------------------------
ROBOTS = ["robot1", "robot2"]
# A test marked FLEET runs over a fleet's profile, of ROBOTS (the profile fixture's indirect parameter).
FLEET = pytest.mark.parametrize("profile", [ROBOTS], indirect=True, ids=["fleet"])


def payloads(collector: Collector) -> set[bytes]:
    return {message["payload"] for message in collector.messages}


@FLEET
def test_a_robots_follower_drives_its_own_robot_only(as_role):
    operator = as_role("operator")  # one session hears both robots' cmd_vel, in the order routed
    commands = {robot: Collector(operator, f"{robot}/cmd_vel", None) for robot in ROBOTS}
    followers = {robot: as_role("follower", robot) for robot in ROBOTS}
    put_until_seen(followers["robot2"], "robot2/cmd_vel", b"robot2's own", commands["robot2"])
    put_until_seen(followers["robot1"], "robot1/cmd_vel", b"robot1's own", commands["robot1"])
    # robot1's follower knows robot2/cmd_vel has a subscriber, so its put is sent: the router drops it.
    trespass = followers["robot1"].declare_publisher("robot2/cmd_vel")
    wait_matched(trespass)
    trespass.put(b"robot1 into robot2")
    # (sent after it on the same links: once this arrives, so would have the trespass)
    put_until_seen(followers["robot1"], "robot1/cmd_vel", b"robot1's, after", commands["robot1"])
    assert payloads(commands["robot2"]) == {b"robot2's own"}
    trespass.undeclare()


@FLEET
def test_a_robots_detector_reads_its_own_robots_frames_only(as_role):
    sources = {robot: as_role("simulator", robot) for robot in ROBOTS}
    detector = as_role("detector", "robot1")
    own, other = (Collector(detector, f"{robot}/camera/image_raw", None) for robot in ROBOTS)
    viewer = as_role("viewer", "robot1")  # robot1's own
    watching, watching_own = Collector(viewer, "robot2/**", None), Collector(viewer, "robot1/camera/image_raw", None)
    # robot2's own detector and the fleet-wide one (a process serving every robot) get robot2's frames
    robot2_frames = [Collector(as_role("detector", robot), "robot2/camera/image_raw", None)
                     for robot in ("robot2", "")]
    put_until_seen(sources["robot2"], "robot2/camera/image_raw", b"robot2's frame", robot2_frames[0])
    robot2_frames[1].wait_for(lambda messages: messages, 10, "robot2's frame at the fleet-wide detector")
    # (routed after robot2's frame went out to every subscriber allowed it)
    put_until_seen(sources["robot1"], "robot1/camera/image_raw", b"robot1's frame", own)
    watching_own.wait_for(lambda messages: messages, 10, "robot1's frame at robot1's viewer")
    assert other.messages == watching.messages == []


@FLEET
def test_a_robots_service_joins_with_the_robots_credentials_copied_to_it(profile, secure_router, as_role, tmp_path):
    # On the robot: its own folder only, no fleet-wide credentials to fall back on.
    on_robot = tmp_path / "on-robot"
    shutil.copytree(profile / "robots" / "robot1", on_robot / "robots" / "robot1")
    endpoint = f"tls/localhost:{secure_router}"
    follower = start_service("follower", endpoint, tmp_path, "--namespace", "robot1", "--secure", str(on_robot))
    # On the server: one locator for every robot, with the fleet-wide locator's credentials.
    locator = start_service("locator", endpoint, tmp_path, "--namespaces", ",".join(ROBOTS), "--secure", str(profile))
    try:
        Liveliness(as_role("viewer", "robot1"), "robot1").wait("follower", timeout=40)
        Liveliness(as_role("viewer", "robot2"), "robot2").wait("locator", timeout=40)
        # (the fleet-wide viewer's view: every robot's tokens, as `balltrack status` reads them)
        fleet_viewer = as_role("viewer")
        wait_until(lambda: services_by_namespace(fleet_viewer) == {"robot1": {"follower", "locator"},
                                                                   "robot2": {"locator"}},
                   20, "every robot's services in the fleet-wide viewer's view", follower, locator)
    finally:
        assert [follower.stop(), locator.stop()] == [0, 0], follower.output() + locator.output()
    elsewhere = start_service("follower", endpoint, tmp_path, "--namespace", "robot2", "--secure", str(on_robot))
    assert elsewhere.popen.wait(60) == 2
    assert (f"--secure: no {on_robot}/robots/robot2/follower/client.json5 nor {on_robot}/follower/client.json5"
            in elsewhere.output()), elsewhere.output()


@FLEET
def test_one_process_per_service_serves_every_robot_under_the_supervisor(profile, secure_router, tmp_path):
    """A secure fleet under the supervisor: ``deploy start --namespaces`` with the fleet-wide
    roles, a simulator holding both robots among them."""
    run_dir = tmp_path / "run"
    command = [sys.executable, "-m", "balltrack.deploy", "start", "--secure", str(profile), "--connect",
               f"tls/localhost:{secure_router}", "--services", "locator,follower,simulator",
               "--namespaces", ",".join(ROBOTS), "--set", "simulator.robots=2", "--set", "simulator.width=160",
               "--set", "simulator.height=120", "--run-dir", str(run_dir), "--wait", "60"]
    started = subprocess.run(command, cwd=REPO, env=process_environment(), capture_output=True, text=True, timeout=120)
    try:
        assert started.returncode == 0, started.stdout + started.stderr
        shown = subprocess.run([sys.executable, "-m", "balltrack", "status", "--run-dir", str(run_dir), "--json"],
                               cwd=REPO, env=process_environment(), capture_output=True, text=True, timeout=60)
        children = json.loads(shown.stdout)["children"]
        assert {name: {label: entry["alive"] for label, entry in child["services"].items()}
                for name, child in children.items() if name != "simulator"} == {
            service: {f"{robot}/{service}": True for robot in ROBOTS} for service in ("locator", "follower")}
        assert children["simulator"]["alive"] is True
    finally:
        stopped = subprocess.run([sys.executable, "-m", "balltrack.deploy", "stop", "--run-dir", str(run_dir)],
                                 cwd=REPO, env=process_environment(), capture_output=True, text=True, timeout=120)
        assert stopped.returncode == 0, stopped.stdout + stopped.stderr


@FLEET
def test_a_simulator_holding_the_fleet_serves_each_robots_own_services(profile, secure_router, as_role, tmp_path):
    simulator = start_service("simulator", f"tls/localhost:{secure_router}", tmp_path, "--secure", str(profile),
                              *SMALL, "--set", "robots=2", "--set", "pacing=realtime")
    try:
        # Each robot's own detector gets that robot's frames (and, by the rules, no other's).
        for robot in ROBOTS:
            Collector(as_role("detector", robot), f"{robot}/camera/image_raw", "Image").wait_count(2, 40)
        # A person drives one robot's part of the world through that robot's sim/control.
        reply = send_command(as_role("operator"), {"op": "place_robot", "x": 0.5, "y": 0.0, "yaw": 0.0},
                             namespace="robot2")
        assert reply["ok"], reply
        Liveliness(as_role("viewer")).wait("simulator", timeout=20)  # its own token, outside the robots'
    finally:
        assert simulator.stop() == 0, simulator.output()
