"""`voicectl bus-secrets DIR`: what a secured bus needs, made once per deployment.

The router configuration shipped beside this module (`secure-router.json5`) turns on TLS,
a user and password per service and access control. This writes what it points to, and
one client configuration per service, so that every process starts with
`--config DIR/<service>.json5` and nothing secret is ever typed on a command line:

- `ca.pem`, `ca.key`: a certificate authority of this deployment only;
- `router.pem`, `router.key`: the router's certificate, for the names clients use;
- `passwords`: the router's `user:password` dictionary;
- `router.json5`: the shipped router configuration, its paths pointing into DIR;
- `<user>.json5`: a client configuration per user (endpoint, CA, user and password).

Everything but the certificates is readable by its owner only.
"""

from __future__ import annotations

import ipaddress
import json
import secrets
from pathlib import Path

from cryptography import x509
from cryptography.hazmat.primitives import hashes, serialization
from cryptography.hazmat.primitives.asymmetric import ec
from cryptography.x509.oid import NameOID

from shared.errors import VoicectlError

from .cert import certificate_builder, key_pem, server_certificate, write_file

ROUTER_TEMPLATE = Path(__file__).with_name("secure-router.json5")
CONTAINER_DIR = "/etc/voicectl/bus"
"""Where the template expects DIR: the path the containers mount it at."""
USERS = ("converter", "stt", "supervisor", "executor", "robot", "panel", "operator", "observer")
"""One per service; `robot` is zenoh-bridge-ros2dds or voicectl sim, `operator` the
`voicectl` commands a person types, `observer` a read-only tool (Zenoh's CLI)."""
LOCAL_NAMES = ("localhost", "127.0.0.1")
VALID_DAYS = 3650
PORT = 7447


class SecretsExist(VoicectlError, FileExistsError):
    """DIR already holds a deployment's secrets: writing new ones would lock its services out."""


def write_bus_secrets(directory: Path, hosts: list[str], port: int = PORT) -> list[Path]:
    """Write a deployment's bus secrets into `directory`; the files written. Clients
    connect to the first of `hosts` (the router's name or address as they see it)."""
    directory = directory.expanduser().resolve()
    if (directory / "passwords").exists():
        raise SecretsExist(
            f"{directory} already holds bus secrets; remove it or choose another directory"
        )
    directory.mkdir(parents=True, exist_ok=True, mode=0o700)
    ca_key, ca_certificate = _authority()
    router_key = ec.generate_private_key(ec.SECP256R1())
    names = list(dict.fromkeys([*hosts, *LOCAL_NAMES]))
    router_certificate = _signed(router_key, names, ca_key, ca_certificate)
    passwords = {user: secrets.token_urlsafe(24) for user in USERS}
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
            ROUTER_TEMPLATE.read_text().replace(CONTAINER_DIR, str(directory)).encode(),
        ),
    ]
    endpoint = f"tls/{_endpoint_host(hosts[0] if hosts else LOCAL_NAMES[0])}:{port}"
    for user, password in passwords.items():
        client = {
            "mode": "client",
            "connect": {"endpoints": [endpoint]},
            "transport": {
                "link": {"tls": {"root_ca_certificate": str(directory / "ca.pem")}},
                "auth": {"usrpwd": {"user": user, "password": password}},
            },
        }
        text = json.dumps(client, indent=2) + "\n"
        written.append(write_file(directory / f"{user}.json5", text.encode(), private=True))
    return written


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
