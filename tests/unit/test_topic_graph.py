"""Who declared a key (``balltrack topic list/info``), from the router's admin space as
``Graph.query`` reads it, here filled in directly."""

from balltrack.cli.introspect import Graph, rate
from balltrack.common.keys import Keys

JOINED, ALONE = "aaaaaaaaaaaa", "bbbbbbbbbbbb"  # a process of three services, and the simulator


def graph_of(declared: dict[str, dict[str, set[str]]]) -> Graph:
    graph = Graph()
    for kind, keys in declared.items():
        for key, zids in keys.items():
            graph.declared[kind][key] |= zids
    return graph


def test_the_services_of_a_joined_process_are_told_apart_by_the_key():
    keys = Keys("robot1")
    graph = graph_of({
        "token": {f"robot1/alive/{name}": {JOINED} for name in ("detector", "locator", "follower")}
                 | {"robot1/alive/simulator": {ALONE}},
        "publisher": {"robot1/detected_ball_3d": {JOINED}, "robot1/cmd_vel": {JOINED},
                      "robot1/detected_ball": {JOINED}, "robot1/locator/stats": {JOINED},
                      "robot1/camera/image_raw": {ALONE}, "robot1/sim/ground_truth": {"cccccccccccc"}},
        "subscriber": {"robot1/camera/image_raw": {JOINED}, "robot1/cmd_vel": {ALONE}},
    })
    assert graph.names() == {JOINED: ["detector", "follower", "locator"], ALONE: ["simulator"]}
    # (each of the process's keys was credited to one of its services, whichever token came last)
    assert graph.who("publisher", "robot1/detected_ball_3d", keys) == ["locator"]
    assert graph.who("publisher", "robot1/cmd_vel", keys) == ["follower"]
    assert graph.who("publisher", "robot1/detected_ball", keys) == ["detector"]
    assert graph.who("publisher", "robot1/locator/stats", keys) == ["locator"]
    assert graph.who("publisher", "robot1/camera/image_raw", keys) == ["simulator"]
    # a subscriber: the key table names publishers only, so the process as it was started
    assert graph.who("subscriber", "robot1/camera/image_raw", keys) == ["detector+follower+locator"]
    assert graph.who("subscriber", "robot1/cmd_vel", keys) == ["simulator"]
    # a session with no token: its Zenoh id, shortened
    assert graph.who("publisher", "robot1/sim/ground_truth", keys) == ["cccccccc"]
    # Listed from the root, the same keys: in robot1's namespace, as robot1 lists them.
    root = Keys("")
    assert graph.keys_of("robot1/cmd_vel", root).namespace == "robot1"
    assert graph.who("publisher", "robot1/cmd_vel", root) == ["follower"]
    assert graph.keys_of("cmd_vel", root).namespace == "" and graph.keys_of("other/x", root).namespace == ""


def test_a_key_seen_once_in_the_window_has_the_rate_of_one_per_window():
    # (a 1 Hz key, camera_info or stats, in the default 1 s window: it showed 0.00)
    assert rate([], 1.0) == 0.0
    assert rate([(5.0, 10)], 1.0) == 1.0 and rate([(5.0, 10)], 2.0) == 0.5
    assert rate([(5.0, 10), (5.5, 10), (6.0, 10)], 1.0) == 2.0
