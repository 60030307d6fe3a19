"""`voicectl bus-secrets DIR --robot NAME...`: what a secured bus needs, made once per
deployment.

The router configuration shipped beside this module (`secure-router.json5`) turns on TLS,
a user and password per service and access control. This writes what it points to, and
one client configuration per user, so that every process starts with
`--config DIR/<user>.json5` and nothing secret is ever typed on a command line:

- `ca.pem`, `ca.key`: a certificate authority of this deployment only;
- `router.pem`, `router.key`: the router's certificate, for the names clients use;
- `passwords`: the router's `user:password` dictionary;
- `router.json5`: the shipped router configuration, its paths pointing into DIR and each
  robot's access rules written in;
- `<user>.json5`: a client configuration per user (endpoint, CA, user and password).

The host's services (converter, stt, supervisor, panel) and people's tools serve every
robot and have one user each. An executor or a robot side speaks for one robot only, so
each robot NAME has two users, `executor-NAME` and `robot-NAME`, whose rules name that
robot's keys: one robot's executor cannot pose as another's. The robot named `robot`,
the one every `--robot` defaults to, also gets its files under the plain names
`executor.json5` and `robot.json5` (the same users), as deployments of one robot always
had them.

Why a template with rules written in, rather than the whole configuration built here:
the shared part is what a reader audits, and stays a commented file beside this module;
only what repeats per robot is generated, as JSON (which JSON5 reads) at the three
"each robot's" lines of the template, each robot's block under a comment naming it.

Everything but the certificates and the router's configuration is readable by its owner
only.
"""

from __future__ import annotations

import base64
import ipaddress
import json
import secrets
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from cryptography import x509
from cryptography.hazmat.primitives import hashes, serialization
from cryptography.hazmat.primitives.asymmetric import ec
from cryptography.x509.oid import NameOID

from voicectl.shared.errors import VoicectlError
from voicectl.shared.keys import RobotKeys, check_chunk
from voicectl.shared.robot.keys import RobotNames, bridge_tokens, check_ros_name

from .cert import certificate_builder, key_pem, server_certificate, write_file

ROUTER_TEMPLATE = Path(__file__).with_name("secure-router.json5")
CONTAINER_DIR = "/etc/voicectl/bus"
"""Where the template expects DIR: the path the containers mount it at."""
SHARED_USERS = ("converter", "stt", "supervisor", "panel", "operator", "observer")
"""One per service that serves every robot; `operator` is the `voicectl` commands a
person types, `observer` a read-only tool (Zenoh's CLI)."""
ROBOT_ROLES = ("executor", "robot")
"""What has a user per robot: its executor, and its robot side (zenoh-bridge-ros2dds, or
voicectl sim)."""
DEFAULT_ROBOT = "robot"
"""The robot every `--robot` defaults to: the one the plain `executor.json5` and
`robot.json5` are for."""
SAYS = ["put", "delete", "declare_queryable", "reply", "liveliness_token"]
"""The messages by which a user publishes, serves or announces something."""
EVERYONE = ["deliver", "listen", "ask-history"]
"""The template's rules that every user has."""
ROBOT_MARKERS = {
    "rules": "// --- each robot's rules",
    "subjects": "// --- each robot's subjects",
    "policies": "// --- each robot's policies",
}
"""The template's lines after whose comment each robot's part of a list is written, just
before the `],` that closes the list."""
LOCAL_NAMES = ("localhost", "127.0.0.1")
VALID_DAYS = 3650
PORT = 7447


class SecretsExist(VoicectlError, FileExistsError):
    """DIR already holds a deployment's secrets: writing new ones would lock its services out."""


@dataclass(frozen=True)
class BusRobot:
    """A robot of the deployment, as its access rules need it."""

    name: str
    namespace: str = ""
    """Its ROS namespace, as its bridge and executor use it ('bot1'); '' when it has
    none or it is not known: its velocity topic, actions and robot side's keys are then
    not told apart from another robot's."""

    def __post_init__(self) -> None:
        check_chunk(self.name, "robot name")
        object.__setattr__(self, "namespace", check_ros_name(self.namespace, "ROS namespace"))

    def user(self, role: str) -> str:
        """The user name of this robot's `role` ('executor-bot1')."""
        return f"{role}-{self.name}"


def users(robots: Iterable[BusRobot]) -> list[str]:
    """Every user of a deployment with `robots`."""
    return [*SHARED_USERS, *(robot.user(role) for robot in robots for role in ROBOT_ROLES)]


def client_files(robots: Iterable[BusRobot]) -> dict[str, str]:
    """The client configurations of a deployment with `robots`, by file name without
    `.json5`: each user's, and the default robot's under the plain role names."""
    robots = list(robots)
    files = {user: user for user in users(robots)}
    if any(robot.name == DEFAULT_ROBOT for robot in robots):
        files.update({role: BusRobot(DEFAULT_ROBOT).user(role) for role in ROBOT_ROLES})
    return files


def write_bus_secrets(
    directory: Path,
    hosts: list[str],
    port: int = PORT,
    robots: Iterable[BusRobot] = (BusRobot(DEFAULT_ROBOT),),
) -> list[Path]:
    """Write a deployment's bus secrets into `directory`; the files written. Clients
    connect to the first of `hosts` (the router's name or address as they see it)."""
    robots = list(robots)
    names = [robot.name for robot in robots]
    if not robots or len(set(names)) != len(names):
        raise ValueError(f"robots must be named once each, at least one; got {names}")
    directory = directory.expanduser().resolve()
    if holds_secrets(directory):
        raise SecretsExist(
            f"{directory} already holds bus secrets; remove it or choose another directory"
        )
    directory.mkdir(parents=True, exist_ok=True, mode=0o700)
    ca_key, ca_certificate = _authority()
    router_key = ec.generate_private_key(ec.SECP256R1())
    router_names = list(dict.fromkeys([*hosts, *LOCAL_NAMES]))
    router_certificate = _signed(router_key, router_names, ca_key, ca_certificate)
    passwords = {user: secrets.token_urlsafe(24) for user in users(robots)}
    written = [
        write_file(directory / "ca.pem", _pem(ca_certificate)),
        write_file(directory / "ca.key", key_pem(ca_key), private=True),
        write_file(directory / "router.pem", _pem(router_certificate) + _pem(ca_certificate)),
        write_file(directory / "router.key", key_pem(router_key), private=True),
        write_file(
            directory / "passwords",
            "".join(f"{user}:{password}\n" for user, password in passwords.items()).encode(),
            private=True,
        ),
        write_file(
            directory / "router.json5",
            router_configuration(directory, robots).encode(),
        ),
    ]
    endpoint = f"tls/{_endpoint_host(hosts[0] if hosts else LOCAL_NAMES[0])}:{port}"
    for file, user in client_files(robots).items():
        password = passwords[user]
        client = {
            "mode": "client",
            "connect": {"endpoints": [endpoint]},
            "transport": {
                "link": {"tls": {"root_ca_certificate": str(directory / "ca.pem")}},
                "auth": {"usrpwd": {"user": user, "password": password}},
            },
        }
        text = json.dumps(client, indent=2) + "\n"
        written.append(write_file(directory / f"{file}.json5", text.encode(), private=True))
    return written


def holds_secrets(directory: Path) -> bool:
    """Whether `directory` holds a deployment's bus secrets already."""
    return (directory.expanduser() / "passwords").exists()


def portable_client(directory: Path, name: str, endpoint: str = "") -> str:
    """The client configuration `directory/<name>.json5` made to work anywhere: the CA's
    certificate inside it rather than a path into `directory`, and connecting to
    `endpoint` when given (the router's published port, as another machine reaches it).
    ValueError naming the files there if there is none of that name."""
    path = directory / f"{name}.json5"
    if name == "router" or not path.is_file():
        names = sorted(p.stem for p in directory.glob("*.json5") if p.stem != "router")
        raise ValueError(f"no client '{name}' in {directory}; clients: {', '.join(names)}")
    client = json.loads(path.read_text())
    tls = client["transport"]["link"]["tls"]
    authority = Path(tls.pop("root_ca_certificate"))
    tls["root_ca_certificate_base64"] = base64.b64encode(authority.read_bytes()).decode()
    if endpoint:
        client["connect"]["endpoints"] = [endpoint]
    return json.dumps(client, indent=2) + "\n"


def router_configuration(directory: Path, robots: Iterable[BusRobot]) -> str:
    """The shipped router configuration, its paths pointing into `directory`, with each
    of `robots`' rules, subjects and policies written in."""
    parts: dict[str, list[str]] = {kind: [] for kind in ROBOT_MARKERS}
    for robot in robots:
        for kind, items in robot_access(robot).items():
            parts[kind].append(f"// robot '{robot.name}'")
            parts[kind] += [json.dumps(item, ensure_ascii=False) + "," for item in items]
    lines = ROUTER_TEMPLATE.read_text().replace(CONTAINER_DIR, str(directory)).splitlines()
    for kind, marker in ROBOT_MARKERS.items():
        (at,) = [i for i, line in enumerate(lines) if line.strip().startswith(marker)]
        end = next(i for i in range(at, len(lines)) if lines[i].strip() == "],")
        indent = lines[at][: len(lines[at]) - len(lines[at].lstrip())]
        lines[end:end] = [indent + line for line in parts[kind]]
    return "\n".join(lines) + "\n"


def robot_access(robot: BusRobot) -> dict[str, list[dict[str, Any]]]:
    """The access rules, subjects and policies of one robot's executor and robot side."""
    keys, names = RobotKeys(robot.name), RobotNames(robot.namespace)
    executor, side = robot.user("executor"), robot.user("robot")
    says, asks = f"{executor}/says", f"{executor}/asks"
    side_says = f"{side}/says"
    rules = [
        _rule(says, SAYS, [*keys.executor_says, names.any_cmd_vel, names.any_speed_limit]),
        # The robot's actions; and its supervisor, whom alone it takes orders from.
        _rule(asks, ["query"], [names.any_action, keys.supervisor]),
        _rule(side_says, SAYS, [names.everything, *bridge_tokens(robot.namespace)]),
    ]
    return {
        "rules": rules,
        "subjects": [{"id": user, "usernames": [user]} for user in (executor, side)],
        "policies": [
            {"id": executor, "rules": [*EVERYONE, says, asks], "subjects": [executor]},
            {"id": side, "rules": [*EVERYONE, side_says, "robot-not-voice"], "subjects": [side]},
        ],
    }


def _rule(rule_id: str, messages: list[str], key_exprs: list[str]) -> dict[str, Any]:
    return {
        "id": rule_id,
        "messages": messages,
        "flows": ["ingress"],
        "permission": "allow",
        "key_exprs": key_exprs,
    }


def _authority() -> tuple[ec.EllipticCurvePrivateKey, x509.Certificate]:
    key = ec.generate_private_key(ec.SECP256R1())
    name = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, "voicectl bus CA")])
    certificate = (
        certificate_builder(name, name, key, VALID_DAYS)
        .add_extension(x509.BasicConstraints(ca=True, path_length=0), critical=True)
        .add_extension(
            x509.KeyUsage(
                digital_signature=False,
                content_commitment=False,
                key_encipherment=False,
                data_encipherment=False,
                key_agreement=False,
                key_cert_sign=True,
                crl_sign=True,
                encipher_only=False,
                decipher_only=False,
            ),
            critical=True,
        )
        .add_extension(x509.SubjectKeyIdentifier.from_public_key(key.public_key()), critical=False)
        .sign(key, hashes.SHA256())
    )
    return key, certificate


def _signed(
    key: ec.EllipticCurvePrivateKey,
    hosts: list[str],
    ca_key: ec.EllipticCurvePrivateKey,
    ca_certificate: x509.Certificate,
) -> x509.Certificate:
    return (
        server_certificate(hosts, key, issuer=ca_certificate.subject, days=VALID_DAYS)
        .add_extension(
            x509.AuthorityKeyIdentifier.from_issuer_public_key(ca_key.public_key()),
            critical=False,
        )
        .sign(ca_key, hashes.SHA256())
    )


def _endpoint_host(host: str) -> str:
    try:
        address = ipaddress.ip_address(host)
    except ValueError:
        return host
    return f"[{address}]" if address.version == 6 else str(address)


def _pem(certificate: x509.Certificate) -> bytes:
    return certificate.public_bytes(serialization.Encoding.PEM)
