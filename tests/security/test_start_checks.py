"""What the bridge checks before it starts: an exposed port needs --auth-file (or --insecure),
and every file it is given is named, with the user, when it cannot be read; add-principal
makes a file the bridge's user can read and nobody else."""

from __future__ import annotations

import argparse
import getpass
import grp
import pwd
import stat
import subprocess
import sys
from pathlib import Path

import pytest

from rosbridge_core.security import exposure_refusal
from rosbridge_core.security.auth import AuthFileError, add_principal, load_auth_file
from tests.helpers import ROOT, BridgeProcess, ros_env
from tests.security.support import AuthFile, Certs


def _bridge(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "bridge_server", *args], cwd=ROOT,
                          env=ros_env(), capture_output=True, text=True, timeout=60)


@pytest.mark.parametrize(
    ("host", "auth_file", "insecure", "refused"),
    [
        ("0.0.0.0", False, False, True),
        ("::", False, False, True),
        ("", False, False, True),
        ("192.168.1.5", False, False, True),
        ("robot.local", False, False, True),
        ("0.0.0.0", True, False, False),
        ("0.0.0.0", False, True, False),
        ("127.0.0.1", False, False, False),
        ("::1", False, False, False),
        ("localhost", False, False, False),
    ],
)
def test_exposed_port_needs_an_auth_file_or_insecure(host: str, auth_file: bool, insecure: bool,
                                                     refused: bool) -> None:
    """A non-loopback --host without --auth-file is refused unless --insecure says so."""
    args = argparse.Namespace(host=host, auth_file="auth.toml" if auth_file else None,
                              insecure=insecure)
    reason = exposure_refusal(args)
    assert (reason is not None) == refused
    if reason is not None:
        assert "--auth-file" in reason and "--insecure" in reason


def test_bridge_refuses_an_open_exposed_port_in_one_line() -> None:
    """`--host 0.0.0.0` alone exits 2 with one line saying what to add; nothing listens."""
    out = _bridge("--host", "0.0.0.0", "--port", "0")
    assert out.returncode == 2
    assert out.stderr.count("\n") == 1 and "refusing to start" in out.stderr
    assert "--auth-file" in out.stderr and "--insecure" in out.stderr
    assert "listening" not in out.stderr


def test_insecure_starts_and_warns_at_every_start() -> None:
    """With --insecure the bridge serves an exposed port, and logs the warning each start."""
    bridge = BridgeProcess(args=["--host", "0.0.0.0", "--insecure"])
    for _ in range(2):
        first = len(bridge.lines)
        bridge.start()
        try:
            bridge.wait_for_line(r"SECURITY: listening on 0\.0\.0\.0 with neither", start=first)
        finally:
            bridge.stop()


@pytest.mark.parametrize("option", ["--certfile", "--keyfile", "--client-ca", "--auth-file"])
def test_a_missing_file_is_named_with_the_user(option: str, certs: Certs, auth: AuthFile,
                                               tmp_path: Path) -> None:
    """Each file option that points nowhere stops the bridge with one line naming the option,
    the file and the user it runs as."""
    given = {"--certfile": str(certs.server), "--auth-file": str(auth.path)}
    missing = str(tmp_path / "nope.pem")
    given[option] = missing
    out = _bridge("--port", "0", *[a for kv in given.items() for a in kv])
    assert out.returncode == 1, out.stderr
    assert f"cannot start: {option}: cannot read {missing} as user {getpass.getuser()}: " \
           "No such file or directory" in out.stderr
    assert "Traceback" not in out.stderr


def test_a_file_that_is_no_certificate_is_named(tmp_path: Path) -> None:
    """A certificate file that is not PEM is named in the one-line refusal."""
    bad = tmp_path / "server.pem"
    bad.write_text("not a certificate\n")
    out = _bridge("--port", "0", "--certfile", str(bad))
    assert out.returncode == 1
    assert f"--certfile {bad}: not a usable PEM certificate" in out.stderr
    assert "Traceback" not in out.stderr


def test_an_unreadable_auth_file_names_the_user(tmp_path: Path) -> None:
    """An auth file the bridge cannot read says which user could not (a reload says so too)."""
    with pytest.raises(AuthFileError, match=rf"cannot read {tmp_path} as user "
                                            rf"{getpass.getuser()}: Is a directory"):
        load_auth_file(tmp_path)


def test_add_principal_makes_the_missing_folder_owned_for_the_bridge(tmp_path: Path) -> None:
    """add-principal into a folder that does not exist makes it (750, the owner's group) and
    the file (600, the owner's), prints only the token, and exits 0."""
    path = tmp_path / "etc" / "roslibpy-lite" / "auth.toml"
    owner = pwd.getpwnam("nobody")
    out = subprocess.run(
        [sys.executable, "-m", "bridge_server", "add-principal", "bob", "--role", "viewer",
         "--owner", "nobody", "--auth-file", str(path)],
        cwd=ROOT, env=ros_env(), capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    assert len(out.stdout.split()) == 1  # the token
    folder, file = path.parent.stat(), path.stat()
    assert stat.S_IMODE(folder.st_mode) == 0o750 and folder.st_gid == owner.pw_gid
    assert stat.S_IMODE(file.st_mode) == 0o600
    assert (file.st_uid, file.st_gid) == (owner.pw_uid, owner.pw_gid)
    assert grp.getgrgid(folder.st_gid).gr_name == grp.getgrgid(owner.pw_gid).gr_name
    assert [p.name for p in load_auth_file(path).principals] == ["bob"]


def test_add_principal_keeps_the_owner_when_it_adds_and_removes(tmp_path: Path) -> None:
    """Adding another principal or removing one leaves the file its owner's."""
    from rosbridge_core.security.auth import remove_principal

    path = tmp_path / "auth.toml"
    nobody = pwd.getpwnam("nobody")
    add_principal(path, "bob", "viewer", owner="nobody")
    add_principal(path, "carol", "viewer")
    remove_principal(path, "bob")
    assert (path.stat().st_uid, path.stat().st_gid) == (nobody.pw_uid, nobody.pw_gid)


def test_add_principal_names_an_unknown_owner(tmp_path: Path) -> None:
    """--owner of a user this machine does not know: one line, exit 1, no file made."""
    path = tmp_path / "auth.toml"
    out = subprocess.run(
        [sys.executable, "-m", "bridge_server", "add-principal", "bob", "--role", "viewer",
         "--owner", "no-such-user", "--auth-file", str(path)],
        cwd=ROOT, env=ros_env(), capture_output=True, text=True, timeout=60)
    assert out.returncode == 1
    assert out.stderr.strip() == "error: --owner no-such-user: no such user on this machine"
    assert not path.exists()


def test_add_principal_names_a_folder_it_cannot_write(tmp_path: Path) -> None:
    """A folder that cannot be made (a file in its way): one line naming it, exit 2."""
    (tmp_path / "etc").write_text("a file, not a folder")
    path = tmp_path / "etc" / "auth.toml"
    out = subprocess.run(
        [sys.executable, "-m", "bridge_server", "add-principal", "bob", "--role", "viewer",
         "--auth-file", str(path)],
        cwd=ROOT, env=ros_env(), capture_output=True, text=True, timeout=60)
    assert out.returncode == 2
    assert out.stderr.strip().startswith(f"error: {path}: ") and "Traceback" not in out.stderr
