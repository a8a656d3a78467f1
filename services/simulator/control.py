"""Client side of the simulator's ``sim/control`` query, for the CLI, tests and experiments.

Example::

    from balltrack.common.session import open_session
    from balltrack.services.simulator.control import send_command

    session = open_session(["tcp/127.0.0.1:7447"])
    send_command(session, {"op": "place_ball", "id": "tennis", "position": [1.5, 0.2]})
    # -> {"ok": True}, or {"ok": False, "error": "..."}
"""

import msgpack

from balltrack.common import keys
from balltrack.common.keys import Keys
from balltrack.common.messages import MessageError, decode


def send_command(session, request: dict | bytes, namespace: str = "", timeout: float = 5.0) -> dict:
    """Send one SimCommand (``{"op": ..., args}``) and return the simulator's SimReply.

    The request is sent as given (the simulator validates it and answers ``ok: false`` with
    the reason), so this also serves to test bad requests. No simulator answering within
    ``timeout`` seconds gives ``{"ok": False, "error": "no simulator answered ..."}``.
    """
    key = Keys(namespace)(keys.SIM_CONTROL)
    payload = request if isinstance(request, (bytes, bytearray)) else msgpack.packb(
        request, use_bin_type=True)
    for reply in session.get(key, payload=bytes(payload), timeout=timeout):
        if reply.ok is None:
            return {"ok": False, "error": f"{key}: {reply.err.payload.to_string()}"}
        try:
            return decode("SimReply", reply.ok.payload.to_bytes())
        except MessageError as error:
            return {"ok": False, "error": f"{key}: bad reply ({error})"}
    return {"ok": False, "error": f"no simulator answered on {key} within {timeout:g} s"}
