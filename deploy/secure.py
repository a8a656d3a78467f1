"""A secure deployment profile: TLS with mutual authentication, passwords and access control.

    balltrack secure init secure/ --hosts robot,server

Without it, any process that reaches a router's port joins without credentials, reads every
camera frame and may publish ``cmd_vel``. The profile uses Zenoh's own mechanisms only:

* **TLS, both ways** (``transport/link/tls``, ``enable_mtls`` on routers and clients): a CA made
  here signs one certificate per router host and one per role; a client refuses a router whose
  certificate does not name the address it dials, a router refuses a client without a
  certificate from this CA.
* **User and password** (``transport/auth/usrpwd``): one password per role and one per host's
  router (user ``router-<host>``, for joining the other hosts' routers), the router's
  ``dictionary_file`` (``users.txt``, ``user:password`` per line: the roles and the other hosts'
  routers).
* **Access control** (``access_control``, default ``deny``) on every router: a role is a subject
  (its certificate's common name AND its user name) allowed only its own keys: what it puts,
  subscribes to, answers and asks, and its own liveliness token ``alive/<role>``. Another host's
  router passes everything, on router-to-router links only (see :func:`access_control`).

A fleet (``--robots robot1,robot2``): each robot's namespace is its name, and each robot has
credentials of its own for every service role and a viewer (:data:`ROBOT_ROLES`), subject
``<role>@<robot>``, allowed the role's keys under ``<robot>/`` only (no admin space): robot1's
follower cannot put ``robot2/cmd_vel`` nor its detector read robot2's frames. The fleet-wide
roles (:data:`FLEET_ROLES`: viewer, operator, the services one process may run for several
robots, and a simulator holding several robots, also allowed its own keys outside them) get the
same rules for every robot's namespace, and the watchers every robot's liveliness tokens
(``**/alive/*``).

Every process is a Zenoh client of a router: peers would mesh directly, around the routers'
access control. What each role may do is :data:`ROLES` plus the key table
(``common/keys.py``: who publishes what), checked against the running services by
``tests/integration/test_secure.py``.

The folder written by :func:`init_profile`::

    DIR/ca/ca.pem, ca.key        the authority (keep ca.key on this machine only)
    DIR/<host>/router.json5      a router's config, with router.pem, router.key (it listens with
                                 them), router-link.pem, router-link.key (it joins other routers
                                 with them), ca.pem, users.txt
    DIR/<role>/client.json5      a role's config, with <role>.pem, <role>.key, ca.pem, password
    DIR/robots/<robot>/<role>/   with --robots: a robot's own credentials for a role, as above

The json5 files name their other files relative to their own folder (``ca.pem``): balltrack
(``--secure DIR``) resolves them there, so a folder can be copied anywhere; ``zenohd -c`` and
other Zenoh programs resolve them against the current directory (start them in that folder).
Private keys, passwords, the users file and the json5 files holding a password are mode 0600.
:func:`renew` replaces one role's or one host's key, certificate and password in place.
"""

import datetime
import ipaddress
import json
import os
import re
import secrets
import shutil
from dataclasses import dataclass
from pathlib import Path

from balltrack.common import keys as key_table
from balltrack.common.keys import SERVICES, SERVICES_OF_MANY_ROBOTS, Keys, alive_key, namespace_list
from balltrack.common.session import (ROBOT_NAME, ROBOTS_FOLDER, ROUTER_CONFIG, SECURE_CLIENT_CONFIG,
                                      SECURE_FILE_SETTINGS, load_config_file, secure_client_path)

DEFAULT_PORT = 7447
# A leaf certificate lives about two years (CA/Browser Forum's old 825-day limit); `secure renew`
# replaces one, `secure init --force` all. The authority lives ten.
LEAF_DAYS = 825
CA_DAYS = 3650
# Every message kind Zenoh 1.x access control knows.
ALL_MESSAGES = ("put", "delete", "declare_subscriber", "query", "declare_queryable", "reply",
                "liveliness_token", "declare_liveliness_subscriber", "liveliness_query")
# Not roles, not hosts: folder names the profile uses for itself.
RESERVED_NAMES = {"ca"}


class ProfileError(ValueError):
    """A one-line reason init cannot go on (exit 2)."""


@dataclass(frozen=True)
class Role:
    """What one role does on the network beyond the key table's ``publisher`` column.

    ``puts`` are keys it publishes that the table credits to someone else (the operator's
    ``cmd_vel``), ``subscribes``/``queries``/``answers`` are the keys of its subscribers, its
    ``get``s and its queryables, ``watches`` whether it follows the ``alive/*`` tokens."""
    subscribes: tuple[str, ...] = ()
    puts: tuple[str, ...] = ()
    queries: tuple[str, ...] = ()
    answers: tuple[str, ...] = ()
    watches: bool = False
    service: bool = True  # a balltrack service: its own stats, config queryable, alive token


# The ROS side of the bridge: zenoh-bridge-ros2dds's keys under the bridge's `prefix` (ros/ by
# default; a profile for another prefix needs --ros-prefix).
ROS_PREFIX = "ros/"
# Every service's config queryable, and the admin space `balltrack topic` reads (read-only).
ANY_CONFIG = "*/config"
ADMIN_SPACE = "@/**"

# From each service's docstring (services/*/service.py): what it subscribes to and asks.
ROLES: dict[str, Role] = {
    "detector": Role(subscribes=(key_table.IMAGE_RAW,)),
    "locator": Role(subscribes=(key_table.DETECTED_BALL, key_table.CAMERA_INFO),
                    queries=(key_table.CAMERA_INFO,)),
    # clock only with use_sim_time, the demo's setting; one detection key at a time, the one
    # keep_target picks (detected_balls by default), which can be switched live.
    "follower": Role(subscribes=(key_table.DETECTED_BALLS, key_table.DETECTED_BALL, key_table.CLOCK)),
    "simulator": Role(subscribes=(key_table.CMD_VEL, key_table.DETECTED_BALLS),
                      answers=(key_table.CAMERA_INFO,), watches=True),
    "camera": Role(answers=(key_table.CAMERA_INFO,)),
    "ros2_bridge": Role(subscribes=(key_table.DETECTED_BALL, key_table.DETECTED_BALL_3D, key_table.CMD_VEL,
                                    f"{ROS_PREFIX}**"),
                        puts=(key_table.IMAGE_RAW, key_table.CAMERA_INFO, f"{ROS_PREFIX}**")),
    # Watches everything, changes nothing: no put, no query (a config query may set parameters).
    "viewer": Role(subscribes=("**",), queries=(ADMIN_SPACE,), watches=True, service=False),
    # A person or the demo: watches, drives (teleop), asks services and the simulator.
    "operator": Role(subscribes=("**",), puts=(key_table.CMD_VEL,),
                     queries=(ADMIN_SPACE, ANY_CONFIG, key_table.SIM_CONTROL, key_table.CAMERA_INFO),
                     watches=True, service=False),
}


# In a fleet's profile (--robots): the roles that see the whole fleet (a person watching or
# driving, a process serving several robots: `balltrack run locator --namespaces ...`, a
# simulator holding them in one world: `--set robots=N`), and the roles each robot has of its
# own: its services, and a viewer of it alone (`deploy start` on the robot watches its services
# with it). A camera or bridge is one robot's: no fleet-wide one.
FLEET_ROLES = tuple(role for role in ROLES if role in SERVICES_OF_MANY_ROBOTS or role not in SERVICES
                    or role == "simulator")
ROBOT_ROLES = tuple(role for role in ROLES if role in SERVICES or role == "viewer")


@dataclass(frozen=True)
class Identity:
    """Who holds one set of credentials: a role, fleet-wide or one ``robot``'s own."""
    role: str
    robot: str = ""

    @property
    def name(self) -> str:
        """Its user name and access control subject (``follower@robot1``)."""
        return f"{self.role}@{self.robot}" if self.robot else self.role

    def folder(self, directory: Path) -> Path:
        return directory / ROBOTS_FOLDER / self.robot / self.role if self.robot else directory / self.role


def identities(robots: list[str] = ()) -> list[Identity]:
    """Every role; with ``robots`` (a fleet), the fleet-wide roles and each robot's own."""
    if not robots:
        return [Identity(role) for role in ROLES]
    return [*map(Identity, FLEET_ROLES), *(Identity(role, robot) for robot in robots for role in ROBOT_ROLES)]


def table_publishers(spec: key_table.KeySpec) -> set[str]:
    """The services the key table names as ``spec``'s publisher ("simulator or camera")."""
    if spec.publisher == "every service":
        return set(SERVICES)
    return {word for word in re.split(r"\W+", spec.publisher) if word in SERVICES}


@dataclass(frozen=True)
class Permissions:
    """One role's keys per kind of operation, without namespace."""
    puts: tuple[str, ...]
    subscribes: tuple[str, ...]
    answers: tuple[str, ...]
    queries: tuple[str, ...]
    tokens: tuple[str, ...]
    watches: tuple[str, ...]


def permissions(role: str) -> Permissions:
    """The key table's rows for ``role`` plus its :data:`ROLES` entry."""
    entry = ROLES[role]
    puts, answers = [], list(entry.answers)
    for spec in key_table.TABLE:
        if role not in table_publishers(spec) or spec.key.startswith("alive/"):
            continue
        key = spec.key.replace("<service>", role)
        (answers if "->" in spec.message else puts).append(key)
    puts += entry.puts
    tokens = [key_table.alive_key(role)] if entry.service else []
    watches = ["alive/*"] if entry.watches else []
    unique = lambda items: tuple(dict.fromkeys(items))  # noqa: E731 - order kept, repeats dropped
    return Permissions(unique(puts), unique(entry.subscribes), unique(answers), unique(entry.queries),
                       tuple(tokens), tuple(watches))


def _rule(identifier: str, messages: list[str], flows: list[str], key_exprs: list[str]) -> dict:
    return {"id": identifier, "permission": "allow", "flows": flows, "messages": messages,
            "key_exprs": key_exprs}


def access_control(namespace: str = "", hosts: list[str] = (), robots: list[str] = ()) -> dict:
    """The routers' ``access_control`` section: default deny, one subject and policy per role
    (with ``robots``, per identity: see the module docstring), and with ``hosts`` (a cluster)
    the router-to-router links between them.

    A router checks what a client sends it (ingress) and what it forwards to a client (egress),
    so each operation needs both halves: a put is allowed in from its publisher and out to
    each subscriber; a subscriber must also be allowed to declare itself. A declaration is
    allowed where a rule's key expression includes it (``alive/*`` inside ``alive/*``, not
    ``*/stats`` inside ``detector/stats``). A publisher is told of every subscription (egress
    declare_subscriber on ``**``): Zenoh sends a put only where it knows of a subscriber, and
    the detector draws image_out only while someone watches."""
    rules, subjects, policies = [], [], []
    for identity in identities(robots):
        granted, role_rules = permissions(identity.role), []
        spaces = [Keys(robot) for robot in ([identity.robot] if identity.robot else robots)] or [Keys(namespace)]
        # Every robot's liveliness tokens for a fleet-wide watcher: `balltrack status` finds the
        # robots by them, and only a robot's own roles may declare one, under its namespace.
        fleet_watch = bool(robots and not identity.robot)

        def add(kind: str, messages: list[str], flows: list[str], key_list, namespaced: bool = True,
                within: list[Keys] = spaces) -> None:
            # The admin space has no namespace: it shows the whole router (every robot's keys),
            # so a robot's own roles get none of it.
            names = [keys(key) if namespaced and not key.startswith("@/") else key
                     for keys in within for key in key_list if not (identity.robot and key.startswith("@/"))]
            if names:
                role_rules.append(_rule(f"{identity.name} {kind}", messages, flows, list(dict.fromkeys(names))))

        add("put", ["put"], ["ingress"], granted.puts)
        if granted.puts:
            # Who subscribes, as declared: a subscription to `*/stats` is not inside
            # `detector/stats`, and a publisher that never hears of it sends nothing (Zenoh
            # filters puts nobody wants at the writer). This tells a publisher only that
            # someone listens, never what is said. A robot's publisher hears of the other robots'
            # subscriptions too: its put to their keys reaches the router, whose rules drop it.
            role_rules.append(_rule(f"{identity.name} put matching", ["declare_subscriber"], ["egress"], ["**"]))
        add("subscribe", ["declare_subscriber"], ["ingress"], granted.subscribes)
        add("subscribe delivery", ["put"], ["egress"], granted.subscribes)
        add("answer", ["declare_queryable", "reply"], ["ingress"], granted.answers)
        add("answer queries", ["query"], ["egress"], granted.answers)
        add("query", ["query"], ["ingress"], granted.queries)
        add("query replies", ["reply", "declare_queryable"], ["egress"], granted.queries)
        add("token", ["liveliness_token"], ["ingress"], granted.tokens)
        watches = [f"**/{alive_key('*')}"] if fleet_watch and granted.watches else granted.watches
        add("watch", ["declare_liveliness_subscriber", "liveliness_query"], ["ingress"], watches, not fleet_watch)
        add("watch tokens", ["liveliness_token"], ["egress"], watches, not fleet_watch)
        if fleet_watch and identity.role == "simulator":
            # A simulator holding the robots runs outside their namespaces: its own stats,
            # config and token there (each robot's keys are under the robot's, above).
            own, prefix = [Keys(namespace)], f"{identity.role}/"
            answers = [key for key in granted.answers if key.startswith(prefix)]
            add("own put", ["put"], ["ingress"], [key for key in granted.puts if key.startswith(prefix)], within=own)
            add("own answer", ["declare_queryable", "reply"], ["ingress"], answers, within=own)
            add("own answer queries", ["query"], ["egress"], answers, within=own)
            add("own token", ["liveliness_token"], ["ingress"], granted.tokens, within=own)
        rules += role_rules
        subjects.append({"id": identity.name, "cert_common_names": [client_common_name(identity.name)],
                         "usernames": [identity.name]})
        policies.append({"id": identity.name, "rules": [rule["id"] for rule in role_rules],
                         "subjects": [identity.name]})
    if hosts:
        # Routers of a cluster forward for their own clients, whose rights their own router
        # checked: between routers everything passes, on router-to-router links only. Each side
        # of such a link knows the other by something else: the router that accepts it by the
        # link certificate (client use only) AND the user name and password of the router that
        # dialled; the router that dials (usrpwd goes one way: it learns no user name) by the
        # other's listening certificate, which only a TLS server can present (server use only)
        # and which names the address it dialled. A router's certificate or password alone, or
        # with a role's password, is no router.
        rules.append(_rule("router", list(ALL_MESSAGES), ["ingress", "egress"], ["**"]))
        for host in hosts:
            subjects.append({"id": f"router {host} joining", "cert_common_names": [router_link_common_name(host)],
                             "usernames": [router_user(host)]})
            subjects.append({"id": f"router {host} joined", "cert_common_names": [router_common_name(host)]})
        policies.append({"id": "router", "rules": ["router"],
                         "subjects": [f"router {host} {side}" for host in hosts for side in ("joining", "joined")]})
    return {"enabled": True, "default_permission": "deny", "rules": rules, "subjects": subjects,
            "policies": policies}


# -- certificates -----------------------------------------------------------------------------
def client_common_name(identity: str) -> str:
    """A role's certificate (``balltrack follower``), or a robot's own (``balltrack follower@robot1``)."""
    return f"balltrack {identity}"


def router_common_name(host: str) -> str:
    """A router's listening certificate (a TLS server's only)."""
    return f"balltrack router {host}"


def router_link_common_name(host: str) -> str:
    """The certificate a router joins other routers with (a TLS client's only)."""
    return f"balltrack router link {host}"


def router_user(host: str) -> str:
    """The user name a host's router joins the others' with (users.txt splits at the first
    ``:``, which an IPv6 address holds; host names have no ``_``)."""
    return f"router-{host.replace(':', '_')}"


def _private_key():
    from cryptography.hazmat.primitives.asymmetric import ec

    return ec.generate_private_key(ec.SECP256R1())


def _key_pem(private_key) -> bytes:
    from cryptography.hazmat.primitives import serialization

    return private_key.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8,
                                     serialization.NoEncryption())


def _certificate_pem(certificate) -> bytes:
    from cryptography.hazmat.primitives import serialization

    return certificate.public_bytes(serialization.Encoding.PEM)


def _name(common_name: str):
    from cryptography import x509
    from cryptography.x509.oid import NameOID

    return x509.Name([x509.NameAttribute(NameOID.ORGANIZATION_NAME, "balltrack"),
                      x509.NameAttribute(NameOID.COMMON_NAME, common_name)])


def make_authority(days: int = CA_DAYS):
    """(private key, certificate) of a new certificate authority."""
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes

    key = _private_key()
    now = datetime.datetime.now(datetime.timezone.utc)
    name = _name("balltrack CA")
    certificate = (x509.CertificateBuilder().subject_name(name).issuer_name(name)
                   .public_key(key.public_key()).serial_number(x509.random_serial_number())
                   .not_valid_before(now - datetime.timedelta(minutes=5))
                   .not_valid_after(now + datetime.timedelta(days=days))
                   .add_extension(x509.BasicConstraints(ca=True, path_length=0), critical=True)
                   .add_extension(x509.KeyUsage(digital_signature=False, content_commitment=False,
                                                key_encipherment=False, data_encipherment=False,
                                                key_agreement=False, key_cert_sign=True, crl_sign=True,
                                                encipher_only=False, decipher_only=False), critical=True)
                   .add_extension(x509.SubjectKeyIdentifier.from_public_key(key.public_key()), critical=False)
                   .sign(key, hashes.SHA256()))
    return key, certificate


def certificate_names(path: str) -> list[str]:
    """The subject alternative names (host names and addresses) of a PEM certificate file: the
    addresses a client may dial its holder at ([] when it has none)."""
    from cryptography import x509

    certificate = x509.load_pem_x509_certificate(Path(path).read_bytes())
    try:
        alternative = certificate.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
    except x509.ExtensionNotFound:
        return []
    return [*alternative.get_values_for_type(x509.DNSName),
            *(str(address) for address in alternative.get_values_for_type(x509.IPAddress))]


def make_leaf(authority, common_name: str, names: list[str] = (), server: bool = False,
              days: int = LEAF_DAYS):
    """(private key, certificate) signed by ``authority``; ``names`` become subject alternative
    names (an IP address literal as an IP entry). A leaf acts as a TLS client only, or with
    ``server`` as a server only: a router's listening certificate cannot be presented to
    another router as a client's (the access control knows a router that was dialled by it)."""
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes
    from cryptography.x509.oid import ExtendedKeyUsageOID

    authority_key, authority_certificate = authority
    key = _private_key()
    now = datetime.datetime.now(datetime.timezone.utc)
    alternative = []
    for entry in names:
        try:
            alternative.append(x509.IPAddress(ipaddress.ip_address(entry)))
        except ValueError:
            alternative.append(x509.DNSName(entry))
    usages = [ExtendedKeyUsageOID.SERVER_AUTH if server else ExtendedKeyUsageOID.CLIENT_AUTH]
    builder = (x509.CertificateBuilder().subject_name(_name(common_name))
               .issuer_name(authority_certificate.subject).public_key(key.public_key())
               .serial_number(x509.random_serial_number())
               .not_valid_before(now - datetime.timedelta(minutes=5))
               .not_valid_after(now + datetime.timedelta(days=days))
               .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
               .add_extension(x509.KeyUsage(digital_signature=True, content_commitment=False,
                                            key_encipherment=False, data_encipherment=False,
                                            key_agreement=False, key_cert_sign=False, crl_sign=False,
                                            encipher_only=False, decipher_only=False), critical=True)
               .add_extension(x509.ExtendedKeyUsage(usages), critical=False)
               .add_extension(x509.AuthorityKeyIdentifier.from_issuer_public_key(authority_key.public_key()),
                              critical=False))
    if alternative:
        builder = builder.add_extension(x509.SubjectAlternativeName(alternative), critical=False)
    return key, builder.sign(authority_key, hashes.SHA256())


# -- the profile folder -----------------------------------------------------------------------
def _write(path: Path, content: bytes | str, private: bool = False) -> None:
    data = content.encode() if isinstance(content, str) else content
    path.parent.mkdir(parents=True, exist_ok=True)
    # Created with the final mode, so a secret is never readable by others, even briefly.
    descriptor = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600 if private else 0o644)
    with os.fdopen(descriptor, "wb") as handle:
        handle.write(data)
    os.chmod(path, 0o600 if private else 0o644)  # an existing file keeps its mode through open()


def _json5(header: str, settings: dict) -> str:
    comment = "".join(f"// {line}\n".replace("// \n", "//\n") for line in header.strip().splitlines())
    return comment + json.dumps(settings, indent=2) + "\n"


def parse_hosts(text: str) -> list[str]:
    hosts = [item.strip() for item in text.split(",") if item.strip()]
    if not hosts:
        raise ProfileError("--hosts: give at least one host name, e.g. --hosts robot,server")
    for host in hosts:
        if host in ROLES or host in RESERVED_NAMES:
            raise ProfileError(f"--hosts: {host!r} is a role or folder name of the profile; name hosts otherwise")
        if not re.fullmatch(r"[A-Za-z0-9]([A-Za-z0-9.:-]*[A-Za-z0-9])?", host):
            raise ProfileError(f"--hosts: {host!r} is not a host name or address")
    if len(set(hosts)) != len(hosts):
        raise ProfileError(f"--hosts: a host is named twice in {text!r}")
    return hosts


def parse_robots(text: str) -> list[str]:
    """``--robots robot1,robot2``: each robot's namespace, in order; ProfileError (one line)."""
    try:
        robots = namespace_list(text, "--robots")
    except ValueError as error:
        raise ProfileError(str(error)) from None
    for robot in robots:
        # (it names a folder and is part of a user name: users.txt splits at the first ':')
        if not re.fullmatch(ROBOT_NAME, robot):
            raise ProfileError(f"--robots: {robot!r}: a robot's name is letters, digits, '.', '_' and '-' "
                               "(one namespace level)")
    return robots


def router_names(host: str, local: bool) -> list[str]:
    """The names a router's certificate answers to: its host name, and localhost/127.0.0.1
    (the address its own host's processes dial) unless ``local`` is off."""
    return list(dict.fromkeys([host] + (["localhost", "127.0.0.1"] if local else [])))


def _endpoint_host(host: str) -> str:
    return f"[{host}]" if ":" in host else host


def init_profile(directory: Path | str, hosts: list[str], port: int = DEFAULT_PORT, namespace: str = "",
                 local: bool = True, force: bool = False, days: int = LEAF_DAYS, robots: list[str] = ()) -> dict:
    """Write a secure profile into ``directory`` (see the module docstring); a summary.
    ``robots`` (from ``parse_robots``): a fleet, each robot under its own namespace.

    Raises ProfileError if the folder already holds a profile and ``force`` is off."""
    directory = Path(directory)
    Keys(namespace)  # ValueError for a namespace Zenoh cannot route
    if robots and namespace:
        raise ProfileError("--robots: each robot's namespace is its name; no --namespace with it")
    if robots and ROBOTS_FOLDER in hosts:
        raise ProfileError(f"--hosts: {ROBOTS_FOLDER!r} is the folder of the robots' credentials; name hosts otherwise")
    if not 0 < port < 65536:
        raise ProfileError(f"--port: {port} is not a TCP port")
    if directory.exists() and not directory.is_dir():
        raise ProfileError(f"{directory} exists and is not a folder")
    # Anything of a previous profile: its CA, its hosts' and roles' folders (even hosts no longer named).
    previous = [directory / "ca", *(directory / name for name in (*hosts, *ROLES)),
                *(path.parent for path in directory.glob(f"*/{ROUTER_CONFIG}"))]
    if any(directory.glob(f"{ROBOTS_FOLDER}/*/*/{SECURE_CLIENT_CONFIG}")):  # (a fleet's)
        previous.append(directory / ROBOTS_FOLDER)
    existing = list(dict.fromkeys(path.name for path in previous if path.exists()))
    if existing and not force:
        raise ProfileError(f"{directory} already holds a profile ({', '.join(existing[:3])}...); "
                           "--force replaces it (every key and password changes)")
    for name in existing:  # --force: nothing of the old profile survives beside the new one
        shutil.rmtree(directory / name)

    authority = make_authority()
    _write(directory / "ca" / "ca.pem", _certificate_pem(authority[1]))
    _write(directory / "ca" / "ca.key", _key_pem(authority[0]), private=True)

    members = identities(robots)
    passwords = {name: secrets.token_urlsafe(24) for name in (*(member.name for member in members),
                                                              *map(router_user, hosts))}
    acl = access_control(namespace, hosts if len(hosts) > 1 else [], robots)
    tls_common = {"root_ca_certificate": "ca.pem", "enable_mtls": True, "verify_name_on_connect": True}

    for host in hosts:
        folder = directory / host
        _write_router_files(directory, authority, host, router_names(host, local), days)
        # (not its own router's user: no one joins this router as itself)
        _write(folder / "users.txt", "".join(f"{user}:{password}\n" for user, password in passwords.items()
                                             if user != router_user(host)), private=True)
        settings = {
            "mode": "router",
            "listen": {"endpoints": [f"tls/0.0.0.0:{port}"]},
            "connect": {"endpoints": [], "timeout_ms": -1,
                        "retry": {"period_init_ms": 100, "period_max_ms": 500, "period_increase_factor": 1.5}},
            "scouting": {"multicast": {"enabled": False}, "gossip": {"enabled": True}},
            "adminspace": {"enabled": True, "permissions": {"read": True, "write": False}},
            "transport": {
                # Only TLS: a plain tcp/ endpoint added by mistake would not even start.
                "link": {"protocols": ["tls"],
                         "tls": {**tls_common, "listen_private_key": "router.key", "listen_certificate": "router.pem",
                                 "connect_private_key": "router-link.key",
                                 "connect_certificate": "router-link.pem"}},
                # dictionary_file checks clients and the other hosts' routers; user/password are
                # this router's own, for joining another host's router (balltrack deploy start
                # --router-connect).
                "auth": {"usrpwd": {"dictionary_file": "users.txt", "user": router_user(host),
                                    "password": passwords[router_user(host)]}},
            },
            "access_control": acl,
        }
        header = (f"balltrack secure profile: the Zenoh router of host {host}.\n"
                  f"  balltrack router --secure {directory} --host {host}\n"
                  f"  (cd {folder} && zenohd -c router.json5)   # paths are relative to this folder\n"
                  f"Its certificate names: {', '.join(router_names(host, local))}.")
        _write(folder / ROUTER_CONFIG, _json5(header, settings), private=True)

    local_endpoint = f"tls/localhost:{port}" if local else f"tls/{_endpoint_host(hosts[0])}:{port}"
    for member in members:
        role, folder = member.role, member.folder(directory)
        _write_role_files(folder, authority, member, passwords[member.name], days)
        settings = {
            "mode": "client",
            "connect": {"endpoints": [local_endpoint], "timeout_ms": 30000,
                        "retry": {"period_init_ms": 100, "period_max_ms": 500, "period_increase_factor": 1.5}},
            "scouting": {"multicast": {"enabled": False}},
            "transport": {
                "link": {"protocols": ["tls"],
                         "tls": {**tls_common, "connect_private_key": f"{role}.key",
                                 "connect_certificate": f"{role}.pem"}},
                "auth": {"usrpwd": {"user": member.name, "password": passwords[member.name]}},
            },
        }
        serving, of_robot = (f" --namespace {member.robot}", f" of robot {member.robot}") if member.robot else ("", "")
        header = (f"balltrack secure profile: role {role}{of_robot}.\n"
                  f"  balltrack run {role}{serving} --secure {directory}   "
                  "(or --zenoh-config, started in this folder)\n"
                  f"--connect tls/HOST:{port} replaces the endpoint; HOST must be a name of that router's "
                  "certificate.")
        if role not in SERVICES:
            header = header.replace(f"balltrack run {role}", "balltrack status --role " + role)
        _write(folder / SECURE_CLIENT_CONFIG, _json5(header, settings), private=True)
    return {"directory": str(directory), "hosts": hosts,
            "roles": [member.role for member in members if not member.robot],
            "robots": list(robots), "robot_roles": list(ROBOT_ROLES) if robots else [], "port": port,
            "router_names": {host: router_names(host, local) for host in hosts},
            "client_endpoint": local_endpoint}


def _write_router_files(directory: Path, authority, host: str, names: list[str], days: int) -> None:
    """A host's certificates and keys: router.pem to listen with (its ``names``), router-link.pem
    to join other routers with."""
    folder = directory / host
    _write(folder / "ca.pem", _certificate_pem(authority[1]))
    for stem, common_name, server in (("router", router_common_name(host), True),
                                      ("router-link", router_link_common_name(host), False)):
        key, certificate = make_leaf(authority, common_name, names if server else [], server=server, days=days)
        _write(folder / f"{stem}.pem", _certificate_pem(certificate))
        _write(folder / f"{stem}.key", _key_pem(key), private=True)


def _write_role_files(folder: Path, authority, identity: Identity, password: str, days: int) -> None:
    key, certificate = make_leaf(authority, client_common_name(identity.name), days=days)
    _write(folder / "ca.pem", _certificate_pem(authority[1]))
    _write(folder / f"{identity.role}.pem", _certificate_pem(certificate))
    _write(folder / f"{identity.role}.key", _key_pem(key), private=True)
    _write(folder / "password", password + "\n", private=True)


def profile_hosts(directory: Path | str) -> list[str]:
    """The hosts of a profile: its folders holding a router config."""
    return sorted(path.parent.name for path in Path(directory).glob(f"*/{ROUTER_CONFIG}"))


def _replace_password(config_path: Path, password: str) -> None:
    """Put ``password`` in place of the one ``config_path`` holds (transport/auth/usrpwd), the
    rest of the file as it is (hand edits kept)."""
    old = json.loads(load_config_file(config_path).get_json("transport/auth/usrpwd/password"))
    text = config_path.read_text()
    if not old or text.count(json.dumps(old)) != 1:
        raise ProfileError(f"{config_path}: its password is not in the file once, as written; "
                           "`secure init --force` writes the profile anew")
    _write(config_path, text.replace(json.dumps(old), json.dumps(password)), private=True)


def _set_user(users_path: Path, user: str, password: str) -> bool:
    """Replace ``user``'s password in a users.txt; False when it has no such user."""
    lines = users_path.read_text().splitlines()
    found = [index for index, line in enumerate(lines) if line.split(":", 1)[0] == user]
    for index in found:
        lines[index] = f"{user}:{password}"
    if found:
        _write(users_path, "".join(line + "\n" for line in lines), private=True)
    return bool(found)


def renew(directory: Path | str, names: list[str], days: int = LEAF_DAYS) -> dict:
    """A new key, certificate and password for each role or host of ``names``, signed by the
    profile's CA, in place: the rest of the profile (the other keys, the access control) stays.
    A role (or a robot's, ``follower@robot1``): its folder and its line in every host's
    users.txt; a host: its router's certificates, keys and password (router.json5) and its line
    in the other hosts' users.txt.
    The routers read users.txt when they start. {"changed": folders written, "users": the
    users.txt files changed}; ProfileError (one line) for a name the profile lacks or no CA key.
    """
    directory = Path(directory)
    hosts = profile_hosts(directory)
    members = {}
    for name in names:
        if name not in hosts:
            role, at, robot = name.partition("@")
            if role not in (ROBOT_ROLES if at else ROLES) or (at and not re.fullmatch(ROBOT_NAME, robot)):
                raise ProfileError(f"{name!r} is neither a role ({', '.join(ROLES)}), a robot's role "
                                   f"(ROLE@ROBOT) nor a host of {directory} ({', '.join(hosts) or 'none'})")
            members[name] = Identity(role, robot)
            config = members[name].folder(directory) / SECURE_CLIENT_CONFIG
            if not config.is_file():
                raise ProfileError(f"no {config}: renew where the whole profile is")
        elif not (directory / name / "router-link.pem").is_file():
            # (its router.json5 dials with router.pem, which a new one could not do)
            raise ProfileError(f"host {name}'s folder has no router-link.pem (a profile of an earlier "
                               "balltrack): `secure init --force` writes it anew")
    try:
        from cryptography import x509
        from cryptography.hazmat.primitives import serialization

        authority = (serialization.load_pem_private_key((directory / "ca" / "ca.key").read_bytes(), None),
                     x509.load_pem_x509_certificate((directory / "ca" / "ca.pem").read_bytes()))
    except FileNotFoundError as error:
        raise ProfileError(f"no {error.filename}: renew on the machine that keeps the profile's CA") from None
    users_changed = []
    for name in names:
        password = secrets.token_urlsafe(24)
        if name in members:
            folder = members[name].folder(directory)
            _write_role_files(folder, authority, members[name], password, days)
            _replace_password(folder / SECURE_CLIENT_CONFIG, password)
            user = members[name].name
        else:
            _write_router_files(directory, authority, name, certificate_names(directory / name / "router.pem"), days)
            _replace_password(directory / name / ROUTER_CONFIG, password)
            user = router_user(name)
        users_changed += [str(directory / host / "users.txt") for host in hosts
                          if _set_user(directory / host / "users.txt", user, password)]
    changed = [members[name].folder(directory) if name in members else directory / name for name in names]
    return {"changed": list(map(str, changed)), "users": sorted(set(users_changed))}


def client_files(directory: Path | str, role: str) -> Path:
    """A role's client config in a profile (for programs that start processes)."""
    return secure_client_path(directory, role)


__all__ = ["ROLES", "FLEET_ROLES", "ROBOT_ROLES", "Identity", "identities", "parse_robots", "Role", "Permissions",
           "permissions", "access_control", "init_profile", "ProfileError", "parse_hosts", "router_names",
           "make_authority", "make_leaf", "client_files", "renew", "profile_hosts", "SECURE_FILE_SETTINGS"]
