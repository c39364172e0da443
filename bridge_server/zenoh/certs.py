"""``roslibpy-lite-relay certs``: a fleet's CA and the certificates of its relays and robots.

Mutual TLS on the Zenoh links (``--zenoh-mtls``) needs three kinds of certificate, each
with the right names and key usages, and a mistake there fails quietly inside the TLS
stack. This command makes them right the first time, with the maintained ``cryptography``
package::

    roslibpy-lite-relay certs --dir fleet --relay relay1 --relay-host relay.example.com \\
        --robot robot1 --robot robot2

writes into ``fleet/`` (made mode 700):

- ``ca.pem`` and ``ca.key``: the fleet's CA (made once; later runs reuse it, so robots can
  be added). Give ``ca.pem`` to every relay and robot; keep ``ca.key`` offline.
- ``<relay>.pem``/``.key`` per ``--relay``: common name the relay's name (what
  ``--zenoh-relay`` names on another relay), ``subjectAltName`` every ``--relay-host``,
  usable to serve (a router: ``serverAuth``) and to dial (a client of another relay:
  ``clientAuth``).
- ``<robot>.pem``/``.key`` per ``--robot``: common name the robot's name (the router lets
  it use only that robot's keys, ``--zenoh-robot``), ``clientAuth`` only: a robot dials out.

A file that exists is never overwritten: the command refuses, naming it. Keys are written
mode 600.
"""

from __future__ import annotations

import argparse
import datetime
import ipaddress
import os
import sys
from collections.abc import Sequence
from pathlib import Path

try:
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes, serialization
    from cryptography.hazmat.primitives.asymmetric import ec
    from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID
except ModuleNotFoundError as _missing:  # an install without the relay or bridge extra
    from bridge_server._requires import missing_dependency

    missing_dependency(_missing, "relay")

from bridge_server.zenoh import keys
from rosbridge_core.interfaces import BridgeError

__all__ = ["Fleet", "main"]

_CA_DAYS = 3650
_LEAF_DAYS = 825
_NO_USAGE = {"content_commitment": False, "key_encipherment": False, "data_encipherment": False,
             "key_agreement": False, "encipher_only": False, "decipher_only": False}


class Fleet:
    """The fleet's CA in ``folder`` (made on first use) and the certificates it signs."""

    def __init__(self, folder: Path) -> None:
        self.folder = folder
        folder.mkdir(mode=0o700, parents=True, exist_ok=True)
        ca_pem, ca_key = folder / "ca.pem", folder / "ca.key"
        if ca_pem.exists() != ca_key.exists():
            raise BridgeError(f"{folder}: ca.pem and ca.key go together (one of them is "
                              "missing): restore it, or start in an empty folder")
        self.made_ca = not ca_pem.exists()
        if not self.made_ca:
            self.ca = x509.load_pem_x509_certificate(ca_pem.read_bytes())
            loaded = serialization.load_pem_private_key(ca_key.read_bytes(), password=None)
            if not isinstance(loaded, ec.EllipticCurvePrivateKey):
                raise BridgeError(f"{ca_key}: not an EC private key of this command's making")
            self.key = loaded
            return
        self.key = ec.generate_private_key(ec.SECP256R1())
        name = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, "roslibpy-lite fleet CA")])
        self.ca = (_builder(name, name, self.key.public_key(), _CA_DAYS)
                   .add_extension(x509.BasicConstraints(ca=True, path_length=0), critical=True)
                   .add_extension(x509.KeyUsage(digital_signature=False, key_cert_sign=True,
                                                crl_sign=True, **_NO_USAGE), critical=True)
                   .sign(self.key, hashes.SHA256()))
        _write(ca_key, _key_pem(self.key), private=True)
        _write(ca_pem, self.ca.public_bytes(serialization.Encoding.PEM), private=False)

    def issue(self, name: str, hosts: Sequence[str] = (), *, serve: bool) -> tuple[Path, Path]:
        """``<name>.pem`` and ``<name>.key`` signed by the CA: common name ``name``,
        ``hosts`` (DNS names or IP addresses) in ``subjectAltName``; ``serve``: a router's
        (``serverAuth`` and ``clientAuth``), else a dialing robot's (``clientAuth``)."""
        keys.check_robot(name)  # a relay's and a robot's name alike: one key chunk
        pem, key_path = self.folder / f"{name}.pem", self.folder / f"{name}.key"
        for path in (pem, key_path):
            if path.exists():
                raise BridgeError(f"{path} exists: not overwritten (remove it to make it "
                                  "again)")
        if serve and not hosts:
            raise BridgeError(f"relay {name}: give the host names or addresses robots dial "
                              "it at (--relay-host), which its certificate must name")
        key = ec.generate_private_key(ec.SECP256R1())
        subject = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, name)])
        usages = [ExtendedKeyUsageOID.CLIENT_AUTH]
        if serve:
            usages.insert(0, ExtendedKeyUsageOID.SERVER_AUTH)
        builder = (_builder(subject, self.ca.subject, key.public_key(), _LEAF_DAYS)
                   .add_extension(x509.BasicConstraints(ca=False, path_length=None),
                                  critical=True)
                   .add_extension(x509.KeyUsage(digital_signature=True, key_cert_sign=False,
                                                crl_sign=False, **_NO_USAGE), critical=True)
                   .add_extension(x509.ExtendedKeyUsage(usages), critical=False))
        if hosts:
            builder = builder.add_extension(
                x509.SubjectAlternativeName([_alt_name(h) for h in hosts]), critical=False)
        cert = builder.sign(self.key, hashes.SHA256())
        _write(key_path, _key_pem(key), private=True)
        _write(pem, cert.public_bytes(serialization.Encoding.PEM), private=False)
        return pem, key_path


def _builder(subject: x509.Name, issuer: x509.Name, public_key: ec.EllipticCurvePublicKey,
             days: int) -> x509.CertificateBuilder:
    now = datetime.datetime.now(datetime.UTC)
    return (x509.CertificateBuilder()
            .subject_name(subject).issuer_name(issuer).public_key(public_key)
            .serial_number(x509.random_serial_number())
            .not_valid_before(now - datetime.timedelta(minutes=5))
            .not_valid_after(now + datetime.timedelta(days=days)))


def common_name(path: str | Path) -> str | None:
    """The common name of the (first) certificate in the PEM file ``path`` (``None``: it has
    none); ``ValueError`` if the file holds no certificate."""
    cert = x509.load_pem_x509_certificate(Path(path).read_bytes())
    names = cert.subject.get_attributes_for_oid(NameOID.COMMON_NAME)
    return str(names[0].value) if names else None


def _key_pem(key: ec.EllipticCurvePrivateKey) -> bytes:
    return key.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8,
                             serialization.NoEncryption())


def _write(path: Path, data: bytes, private: bool) -> None:
    """Write a new file (never over one), mode 600 for a key."""
    try:
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600 if private else 0o644)
    except FileExistsError:
        raise BridgeError(f"{path} exists: not overwritten (remove it to make it again)"
                          ) from None
    with os.fdopen(fd, "wb") as f:
        f.write(data)


def _alt_name(host: str) -> x509.GeneralName:
    try:
        return x509.IPAddress(ipaddress.ip_address(host))
    except ValueError:
        return x509.DNSName(host)


def parse_args(argv: Sequence[str]) -> argparse.Namespace:
    """The ``certs`` subcommand's command line."""
    p = argparse.ArgumentParser(
        prog="roslibpy-lite-relay certs",
        description="Make a fleet's CA (once) and mutual-TLS certificates for its relays and "
        "robots, with the names and key usages --zenoh-mtls needs. Existing files are never "
        "overwritten.")
    p.add_argument("--dir", required=True, type=Path,
                   help="folder for ca.pem/ca.key and NAME.pem/NAME.key (made mode 700; an "
                   "existing CA in it is reused)")
    p.add_argument("--relay", action="append", default=[], metavar="NAME",
                   help="a relay's certificate (common name NAME; serves and dials); may be "
                   "given several times")
    p.add_argument("--relay-host", action="append", default=[], metavar="HOST",
                   help="a host name or address robots dial the relays at, put in each "
                   "relay certificate's subjectAltName; may be given several times")
    p.add_argument("--robot", action="append", default=[], metavar="NAME",
                   help="a robot's certificate (common name NAME; dials only); may be given "
                   "several times")
    return p.parse_args(list(argv))


def main(argv: Sequence[str]) -> int:
    """``roslibpy-lite-relay certs ...``: 0 once every file is written, 1 with the reason."""
    args = parse_args(argv)
    if not args.relay and not args.robot and (args.dir / "ca.pem").exists():
        print("roslibpy-lite-relay certs: nothing to make: give --relay or --robot",
              file=sys.stderr)
        return 2
    try:
        fleet = Fleet(args.dir)
        made = [args.dir / "ca.pem"] if fleet.made_ca else []
        for relay in args.relay:
            made.append(fleet.issue(relay, args.relay_host, serve=True)[0])
        for robot in args.robot:
            made.append(fleet.issue(robot, serve=False)[0])
    except (OSError, BridgeError, ValueError) as exc:
        print(f"roslibpy-lite-relay certs: {exc}", file=sys.stderr)
        return 1
    for path in made:
        print(f"wrote {path} (and its key)" if path.name != "ca.pem"
              else f"wrote {path} (the fleet's CA; keep ca.key offline)")
    return 0
