"""`voicectl cert HOST...`: a self-signed certificate so browsers on the LAN get a microphone.

Browsers give a page the microphone only in a secure context: https, or http on localhost.
A panel reached as http://192.168.1.20:8000 has none; the same panel served with this
certificate over https has one, once the browser is told to trust it.
"""

from __future__ import annotations

import datetime
import ipaddress
import os
from pathlib import Path

from cryptography import x509
from cryptography.hazmat.primitives import hashes, serialization
from cryptography.hazmat.primitives.asymmetric import ec
from cryptography.x509.oid import NameOID

from voicectl.shared.config import write_secret

VALID_DAYS = 825
"""The longest validity Apple's and Google's browsers accept for a TLS certificate."""


def write_certificate(hosts: list[str], certfile: Path, keyfile: Path) -> None:
    """A P-256 key and a self-signed certificate naming every host (a name or an address)."""
    key = ec.generate_private_key(ec.SECP256R1())
    certificate = server_certificate(hosts, key, issuer=host_name(hosts)).sign(key, hashes.SHA256())
    certfile.parent.mkdir(parents=True, exist_ok=True)
    keyfile.parent.mkdir(parents=True, exist_ok=True)
    write_file(keyfile, key_pem(key), private=True)
    write_file(certfile, certificate.public_bytes(serialization.Encoding.PEM))


def certificate_builder(
    subject: x509.Name, issuer: x509.Name, key: ec.EllipticCurvePrivateKey, days: int
) -> x509.CertificateBuilder:
    """A certificate for `key` valid from five minutes ago (clocks differ) for `days`."""
    now = datetime.datetime.now(datetime.UTC)
    return (
        x509.CertificateBuilder()
        .subject_name(subject)
        .issuer_name(issuer)
        .public_key(key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(now - datetime.timedelta(minutes=5))
        .not_valid_after(now + datetime.timedelta(days=days))
    )


def server_certificate(
    hosts: list[str], key: ec.EllipticCurvePrivateKey, issuer: x509.Name, days: int = VALID_DAYS
) -> x509.CertificateBuilder:
    """A TLS server's certificate for every host, still to be signed by `issuer`."""
    return (
        certificate_builder(host_name(hosts), issuer, key, days)
        .add_extension(x509.SubjectAlternativeName(alt_names(hosts)), critical=False)
        .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
        .add_extension(
            x509.ExtendedKeyUsage([x509.oid.ExtendedKeyUsageOID.SERVER_AUTH]), critical=False
        )
    )


def host_name(hosts: list[str]) -> x509.Name:
    return x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, hosts[0])])


def alt_names(hosts: list[str]) -> list[x509.GeneralName]:
    """Each host as a certificate's subject alternative name: an address or a DNS name."""
    names: list[x509.GeneralName] = []
    for host in hosts:
        try:
            names.append(x509.IPAddress(ipaddress.ip_address(host)))
        except ValueError:
            names.append(x509.DNSName(host))
    return names


def key_pem(key: ec.EllipticCurvePrivateKey) -> bytes:
    return key.private_bytes(
        serialization.Encoding.PEM,
        serialization.PrivateFormat.PKCS8,
        serialization.NoEncryption(),
    )


def write_file(path: Path, content: bytes, private: bool = False) -> Path:
    """Write `content`; a private file is 0600 before a byte is in it, even where a file
    of that name was readable by others (`write_secret`)."""
    if private:
        return write_secret(path, content)
    descriptor = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
    with os.fdopen(descriptor, "wb") as out:
        out.write(content)
    return path
