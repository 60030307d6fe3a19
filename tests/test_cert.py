"""`voicectl cert` and the panel over HTTPS: a self-signed certificate for LAN names and
addresses, a key only its owner reads, and `voicectl web` serving with them."""

from __future__ import annotations

import ipaddress
import os
import ssl
import stat
from pathlib import Path

import httpx
from cryptography import x509

from harness.ports import free_port
from harness.wait import wait_until

from .conftest import Processes, voicectl


def test_cert_names_every_host_and_keeps_the_key_private(tmp_path: Path) -> None:
    done = voicectl("cert", "robot.local", "192.168.1.20", "--out", str(tmp_path))
    assert done.returncode == 0, done.stderr
    certificate = x509.load_pem_x509_certificate((tmp_path / "panel.crt").read_bytes())
    names = certificate.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
    assert names.get_values_for_type(x509.DNSName) == ["robot.local"]
    assert names.get_values_for_type(x509.IPAddress) == [ipaddress.ip_address("192.168.1.20")]
    assert stat.S_IMODE(os.stat(tmp_path / "panel.key").st_mode) == 0o600
    assert "--certfile" in done.stdout


def test_secrets_are_0600_whatever_mode_an_old_file_had(tmp_path: Path) -> None:
    """A key or a token file that exists readable by others (0644) is rewritten 0600, and
    the output says the mode the file has."""
    (tmp_path / "panel.key").write_text("old key")
    (tmp_path / "token").write_text("")
    for old in ("panel.key", "token"):
        os.chmod(tmp_path / old, 0o644)
    done = voicectl("cert", "robot.local", "--out", str(tmp_path))
    assert done.returncode == 0, done.stderr
    assert stat.S_IMODE(os.stat(tmp_path / "panel.key").st_mode) == 0o600
    assert "(mode 0600)" in done.stdout
    assert "PRIVATE KEY" in (tmp_path / "panel.key").read_text()
    environment = {k: v for k, v in os.environ.items() if k != "VOICECTL_TOKEN"}
    made = voicectl("token", "--token-file", str(tmp_path / "token"), env=environment)
    assert made.returncode == 0, made.stderr
    assert stat.S_IMODE(os.stat(tmp_path / "token").st_mode) == 0o600
    assert (tmp_path / "token").read_text().strip() == made.stdout.strip() != ""
    assert sorted(p.name for p in tmp_path.iterdir()) == ["panel.crt", "panel.key", "token"]


def test_the_panel_serves_https_with_it(tmp_path: Path, router: str, processes: Processes) -> None:
    assert voicectl("cert", "127.0.0.1", "--out", str(tmp_path)).returncode == 0
    port = free_port()
    processes.start(
        "voicectl.services.web",
        *("--port", str(port), "--connect", router),
        *("--certfile", str(tmp_path / "panel.crt"), "--keyfile", str(tmp_path / "panel.key")),
    )
    context = ssl.create_default_context(cafile=str(tmp_path / "panel.crt"))
    url = f"https://127.0.0.1:{port}/api/health"

    def healthy() -> bool:
        try:
            return httpx.get(url, verify=context).status_code == 200
        except httpx.HTTPError:
            return False

    wait_until(healthy, 30.0, "the panel over https")
    # plain HTTP on the TLS port gets nothing useful
    try:
        plain = httpx.get(f"http://127.0.0.1:{port}/api/health").status_code
    except httpx.HTTPError:
        plain = 0
    assert plain != 200


def test_half_a_tls_configuration_is_refused(tmp_path: Path) -> None:
    done = voicectl("web", "--certfile", str(tmp_path / "a.crt"))
    assert done.returncode == 2
    assert done.stderr.strip() == "voicectl web: --certfile and --keyfile go together"
