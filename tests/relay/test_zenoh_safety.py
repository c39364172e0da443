"""Safe by default on the Zenoh side, and the certificates that make it so.

A relay listening for Zenoh beyond loopback without mutual TLS, or a robot dialing beyond
loopback without TLS, is refused at start, naming the endpoint and ``--zenoh-insecure``;
with that option it starts and warns. ``roslibpy-lite-relay certs`` makes the fleet's CA and
certificates with the names and key usages mutual TLS needs (tests/relay/test_nat.py runs a
whole tier on them, across a network namespace).
"""

from __future__ import annotations

import re
import stat
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
from cryptography import x509
from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

from bridge_server.zenoh.link import ZenohOptions
from rosbridge_core.interfaces import BridgeError
from tests.helpers import ROOT, ros_env
from tests.relay.procs import Proc
from tests.relay.support import free_port

INSECURE = "--zenoh-insecure"
TLS_FILES = {"tls_ca": "ca.pem", "tls_cert": "relay1.pem", "tls_key": "relay1.key"}


@pytest.fixture(scope="module")
def fleet(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A fleet made by the command: relay1 (at 127.0.0.1 and relay.example.com), robot1."""
    folder = tmp_path_factory.mktemp("fleet") / "certs"
    done = _certs("--dir", str(folder), "--relay", "relay1", "--relay-host", "127.0.0.1",
                  "--relay-host", "relay.example.com", "--robot", "robot1")
    assert done.returncode == 0, done.stderr
    return folder


def _certs(*argv: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "bridge_server.zenoh.relay", "certs", *argv],
                          cwd=ROOT, env=ros_env(), capture_output=True, text=True, timeout=60)


def _tls(fleet: Path) -> dict[str, str]:
    return {k: str(fleet / v) for k, v in TLS_FILES.items()}


@pytest.mark.parametrize(("options", "endpoint"), [
    ({"listen": ["tcp/0.0.0.0:7447"]}, "--zenoh-listen tcp/0.0.0.0:7447"),
    ({"listen": ["tcp/10.0.0.5:7447"]}, "--zenoh-listen tcp/10.0.0.5:7447"),
    ({"listen": ["tls/0.0.0.0:7447"], "tls": True}, "--zenoh-listen tls/0.0.0.0:7447"),
    ({"connect": ["tcp/relay.example.com:7447"]}, "--zenoh-connect tcp/relay.example.com:7447"),
    ({"connect": ["udp/192.0.2.1:7447"]}, "--zenoh-connect udp/192.0.2.1:7447"),
    ({"listen": ["tcp/127.0.0.1:7447"], "connect": ["tcp/router.example.com:7447"]},
     "--zenoh-connect tcp/router.example.com:7447"),
])
def test_links_beyond_this_machine_without_tls_are_refused(
        fleet: Path, options: dict[str, list[str] | bool], endpoint: str) -> None:
    """Each insecure link beyond loopback is refused, naming the endpoint and the option that
    would allow it (TLS without client certificates is not enough for a listener)."""
    tls = _tls(fleet) if options.pop("tls", False) else {}
    link = ZenohOptions(**options, **tls)  # type: ignore[arg-type]
    with pytest.raises(BridgeError) as refused:
        link.config()
    assert endpoint in str(refused.value) and INSECURE in str(refused.value)
    assert "roslibpy-lite-relay certs" in str(refused.value)
    link.insecure = True
    assert link.refusal() is None
    link.config()


@pytest.mark.parametrize("options", [
    {"listen": ["tcp/127.0.0.1:7447"]},
    {"listen": ["tcp/[::1]:7447"]},
    {"connect": ["tcp/localhost:7447"]},
    {"connect": ["tcp/127.0.0.2:7447"]},
    {"listen": ["unixsock-stream//tmp/zenoh.sock"]},
    {"connect": ["tls/relay.example.com:7447"], "tls_ca": "ca"},
    {"listen": ["tls/0.0.0.0:7447"], "mtls": True, "tls_ca": "ca", "tls_cert": "cert",
     "tls_key": "key", "robots": ["robot1"]},  # mutual TLS names who comes in (issue 53)
])
def test_loopback_and_tls_links_need_no_option(fleet: Path, options: dict[str, Any]) -> None:
    """Loopback, a unix socket, a robot dialing TLS and a router asking for certificates are
    allowed as they are."""
    names = {"ca": "ca.pem", "cert": "relay1.pem", "key": "relay1.key"}
    given = {k: str(fleet / names[v]) if k.startswith("tls_") else v for k, v in options.items()}
    link = ZenohOptions(**given)  # type: ignore[arg-type]
    assert link.exposure() is None and link.refusal() is None
    link.config()


@pytest.mark.parametrize(("argv", "option"), [
    (["bridge_server.zenoh.relay", "--zenoh-listen", "tcp/0.0.0.0:7447"], "--zenoh-listen"),
    (["bridge_server", "--no-websocket", "--robot", "robot1", "--zenoh-connect",
      "tcp/0.0.0.0:9"], "--zenoh-connect"),
])
def test_the_command_lines_refuse_an_insecure_link(argv: list[str], option: str) -> None:
    """The relay's and the robot's command lines refuse at start (status 2, one line naming
    the endpoint and --zenoh-insecure), before any Zenoh session."""
    done = subprocess.run([sys.executable, "-m", *argv], cwd=ROOT, env=ros_env(),
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 2, done
    assert "refusing to start" in done.stderr and option in done.stderr, done.stderr
    assert INSECURE in done.stderr


def test_zenoh_insecure_starts_and_warns() -> None:
    """With --zenoh-insecure a robot dialing in clear starts, and says at WARNING what that
    exposes. (0.0.0.0: dialed, it is this machine; nothing answers there.)"""
    robot = Proc([sys.executable, "-m", "bridge_server", "--no-websocket", "--robot", "robot1",
                  "--zenoh-connect", "tcp/0.0.0.0:9", INSECURE], ros_env())
    try:
        robot.wait_for(re.compile(r"WARNING \S+: --zenoh-insecure: --zenoh-connect "
                                  r"tcp/0\.0\.0\.0:9 dials beyond this machine without TLS"))
    finally:
        robot.stop()


def _usages(cert: x509.Certificate) -> list[x509.ObjectIdentifier]:
    return list(cert.extensions.get_extension_for_class(x509.ExtendedKeyUsage).value)


def test_the_certs_command_makes_what_mutual_tls_needs(fleet: Path) -> None:
    """The CA signs a relay certificate that serves and dials under the relay's name and
    hosts, and a robot certificate that only dials, under the robot's name; keys are mode
    600; nothing is overwritten; a later run reuses the CA for a new robot."""
    def load(name: str) -> x509.Certificate:
        return x509.load_pem_x509_certificate((fleet / f"{name}.pem").read_bytes())

    ca, relay, robot = load("ca"), load("relay1"), load("robot1")
    assert ca.extensions.get_extension_for_class(x509.BasicConstraints).value.ca
    for cert, name in ((relay, "relay1"), (robot, "robot1")):
        assert cert.issuer == ca.subject
        cert.verify_directly_issued_by(ca)
        assert cert.subject.get_attributes_for_oid(NameOID.COMMON_NAME)[0].value == name
        assert not cert.extensions.get_extension_for_class(x509.BasicConstraints).value.ca
    assert _usages(relay) == [ExtendedKeyUsageOID.SERVER_AUTH, ExtendedKeyUsageOID.CLIENT_AUTH]
    assert _usages(robot) == [ExtendedKeyUsageOID.CLIENT_AUTH]
    names = relay.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
    assert [str(a) for a in names.get_values_for_type(x509.IPAddress)] == ["127.0.0.1"]
    assert names.get_values_for_type(x509.DNSName) == ["relay.example.com"]
    for key in ("ca.key", "relay1.key", "robot1.key"):
        assert stat.S_IMODE((fleet / key).stat().st_mode) == 0o600

    again = _certs("--dir", str(fleet), "--robot", "robot1")
    assert again.returncode == 1 and "robot1.pem exists: not overwritten" in again.stderr
    more = _certs("--dir", str(fleet), "--robot", "robot2")
    assert more.returncode == 0, more.stderr
    load("robot2").verify_directly_issued_by(ca)
    assert load("ca") == ca


@pytest.mark.parametrize(("argv", "ms"), [([], 3000), (["--zenoh-lease", "0.5"], 500)])
def test_the_lease_reaches_zenoh(argv: list[str], ms: int) -> None:
    """--zenoh-lease (default 3 s, Zenoh's own is 10) is the links' lease in the session's
    configuration, on the relay's command line and the robot's; a lease out of range is named.
    (How soon a cut link is told: ``python -m bench --scenario relay_dead_link``.)"""
    from bridge_server.__main__ import parse_args as bridge_args
    from bridge_server.zenoh.link import options_from_args
    from bridge_server.zenoh.relay import parse_args as relay_args

    for args in (relay_args(["--zenoh-listen", "tcp/127.0.0.1:7447", *argv]),
                 bridge_args(["--robot", "r1", "--zenoh-connect", "tcp/127.0.0.1:7447", *argv])):
        conf = options_from_args(args).config()
        assert conf.get_json("transport/link/tx/lease") == str(ms)
    with pytest.raises(BridgeError, match=r"--zenoh-lease 0: expected 0\.1 to 3600 seconds"):
        ZenohOptions(connect=["tcp/127.0.0.1:7447"], lease=0).config()


def _server_only_cert(fleet: Path, name: str) -> tuple[Path, Path]:
    """A certificate for ``name`` signed by the fleet's CA but usable only to serve
    (``serverAuth``, as a websocket server's recipe makes): wrong for a dialing robot."""
    import datetime

    from cryptography.hazmat.primitives import hashes, serialization
    from cryptography.hazmat.primitives.asymmetric import ec

    ca = x509.load_pem_x509_certificate((fleet / "ca.pem").read_bytes())
    ca_key = serialization.load_pem_private_key((fleet / "ca.key").read_bytes(), None)
    assert isinstance(ca_key, ec.EllipticCurvePrivateKey)
    key = ec.generate_private_key(ec.SECP256R1())
    now = datetime.datetime.now(datetime.UTC)
    cert = (x509.CertificateBuilder()
            .subject_name(x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, name)]))
            .issuer_name(ca.subject).public_key(key.public_key())
            .serial_number(x509.random_serial_number())
            .not_valid_before(now - datetime.timedelta(minutes=5))
            .not_valid_after(now + datetime.timedelta(days=1))
            .add_extension(x509.ExtendedKeyUsage([ExtendedKeyUsageOID.SERVER_AUTH]), False)
            .sign(ca_key, hashes.SHA256()))
    pem, key_path = fleet / f"{name}-server-only.pem", fleet / f"{name}-server-only.key"
    pem.write_bytes(cert.public_bytes(serialization.Encoding.PEM))
    key_path.write_bytes(key.private_bytes(serialization.Encoding.PEM,
                                           serialization.PrivateFormat.PKCS8,
                                           serialization.NoEncryption()))
    return pem, key_path


def test_a_robot_certificate_without_client_auth_is_said_on_both_sides(fleet: Path) -> None:
    """A robot whose certificate allows only server authentication is refused at the TLS
    handshake: the relay's log says why (one WARNING of its own), and the robot, which hears no
    reason, says after a few seconds that no router answered and what its certificate
    needs."""
    from bridge_server.zenoh.exporter import DIAL_WARNING

    endpoint = f"tls/127.0.0.1:{free_port()}"
    cert, key = _server_only_cert(fleet, "robot1")
    ca = str(fleet / "ca.pem")
    relay = Proc([sys.executable, "-m", "bridge_server.zenoh.relay", "--port", "0",
                  "--zenoh-listen", endpoint, "--zenoh-tls-ca", ca,
                  "--zenoh-tls-cert", str(fleet / "relay1.pem"),
                  "--zenoh-tls-key", str(fleet / "relay1.key"), "--zenoh-mtls",
                  "--zenoh-robot", "robot1"], ros_env())
    robot = None
    try:
        relay.wait_for(re.compile(r"relay listening on"))
        robot = Proc([sys.executable, "-m", "bridge_server", "--no-websocket", "--robot",
                      "robot1", "--zenoh-connect", endpoint, "--zenoh-tls-ca", ca,
                      "--zenoh-tls-cert", str(cert), "--zenoh-tls-key", str(key)], ros_env())
        relay.wait_for(re.compile(r"WARNING bridge_server.relay: refused a robot .*: its "
                                  r"certificate's key usage does not allow a client"))
        said = robot.wait_for(re.compile(r"WARNING \S+: robot robot1: no Zenoh router has "
                                         r"answered at tls/\S+ for (\d+) s"),
                              timeout=DIAL_WARNING + 20)
        assert int(said.group(1)) == DIAL_WARNING
        line = next(x for x in robot.lines if "no Zenoh router has answered" in x)
        assert "extendedKeyUsage=clientAuth" in line and "roslibpy-lite-relay certs" in line
        assert "\x1b[" not in "\n".join(relay.lines)  # plain text, not a terminal's colours
    finally:
        for p in (robot, relay):
            if p is not None:
                p.stop()
