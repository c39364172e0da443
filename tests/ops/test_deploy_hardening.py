"""deploy/: each hardening directive of the systemd unit, and the image's unprivileged user
and capabilities, is asserted, so that removing one fails a test (issue 54: deleting
NoNewPrivileges=yes went unnoticed)."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
from pathlib import Path

import pytest

from tests.ops.test_deploy import DOCKERFILE, UNIT, _instructions, _unit_sections

HARDENING = {
    "NoNewPrivileges": "yes",
    "ProtectSystem": "strict",
    "ProtectHome": "yes",
    "PrivateTmp": "yes",
    "ProtectKernelTunables": "yes",
    "ProtectKernelModules": "yes",
    "ProtectControlGroups": "yes",
    "LockPersonality": "yes",
    "RestrictAddressFamilies": "AF_INET AF_INET6 AF_UNIX AF_NETLINK",
}
"""The unit's hardening, directive by directive (RestrictAddressFamilies: the families the
bridge uses, tests/ops/test_deploy.py, and no more)."""

SYSTEMD_CHECKS = {
    "User=/DynamicUser=", "NoNewPrivileges=", "ProtectSystem=", "ProtectHome=", "PrivateTmp=",
    "ProtectKernelTunables=", "ProtectKernelModules=", "ProtectControlGroups=",
    "LockPersonality=", "RestrictAddressFamilies=~AF_PACKET", "RestrictAddressFamilies=~…",
}
"""The checks of ``systemd-analyze security`` that the unit's hardening passes."""

SERVICE_USER = "roslibpy-bridge"
IMAGE_UID = 999
"""The image's user's uid: the header's ``add-principal --owner`` gives it the files."""


@pytest.mark.parametrize("directive", sorted(HARDENING))
def test_unit_keeps_its_hardening_directive(directive: str) -> None:
    """The unit's [Service] section sets the directive once, to its hardened value."""
    service = _unit_sections(UNIT.read_text())["Service"]
    assert directive in service, f"{UNIT.name} lost {directive}="
    (value,) = service[directive]
    assert value.split() == HARDENING[directive].split(), f"{directive}={value}"


def test_unit_runs_as_an_unprivileged_user_with_no_capabilities() -> None:
    """User and Group are the service user (not root), and nothing hands it capabilities
    or a privileged start."""
    service = _unit_sections(UNIT.read_text())["Service"]
    assert service["User"] == [SERVICE_USER] and service["Group"] == [SERVICE_USER]
    granted = {"AmbientCapabilities", "PermissionsStartOnly", "DynamicUser"} & set(service)
    assert not granted, f"{UNIT.name} sets {sorted(granted)}"
    assert not any(cmd.startswith(("+", "!")) for key, cmds in service.items()
                   if key.startswith("Exec") for cmd in cmds), "a command runs privileged"


@pytest.mark.skipif(shutil.which("systemd-analyze") is None, reason="systemd-analyze missing")
def test_systemd_reads_the_units_hardening_as_set(tmp_path: Path) -> None:
    """systemd's own reading of the unit (``systemd-analyze security --offline``) counts
    each of the unit's hardening checks as passed."""
    unit = tmp_path / UNIT.name
    unit.write_text(UNIT.read_text())
    out = subprocess.run(["systemd-analyze", "security", "--offline=true", "--json=short",
                          str(unit)], capture_output=True, text=True, timeout=60, check=True)
    passed = {check["name"] for check in json.loads(out.stdout) if check["set"]}
    assert passed >= SYSTEMD_CHECKS, f"systemd finds unset: {sorted(SYSTEMD_CHECKS - passed)}"


def test_image_runs_as_its_unprivileged_user() -> None:
    """The image makes a system user with the documented uid, and its entry point runs as
    that user (the last USER before ENTRYPOINT), not root."""
    text = DOCKERFILE.read_text()
    steps = _instructions(text)
    made = [re.search(r"useradd\s+(?P<opts>.*?)\s(?P<name>[\w-]+)\s*$", rest)
            for word, rest in steps if word == "RUN" and "useradd" in rest]
    assert len(made) == 1 and made[0] is not None, "the image makes no user of its own"
    name, opts = made[0]["name"], made[0]["opts"].split()
    assert "--system" in opts and opts[opts.index("--uid") + 1] == str(IMAGE_UID), opts
    words = [word for word, _ in steps]
    users = [rest for word, rest in steps[:words.index("ENTRYPOINT")] if word == "USER"]
    assert users and users[-1] == name, f"the entry point runs as {users[-1:] or 'root'}"
    header = text.partition("FROM")[0]
    assert f"--owner {IMAGE_UID}" in header and f"uid {IMAGE_UID}" in header


def test_image_needs_and_gains_no_capability() -> None:
    """No step grants a capability or a setuid bit, the bridge listens on an unprivileged
    port, and the documented ``docker run`` drops every capability and forbids gaining new
    privileges (never --privileged or --cap-add)."""
    text = DOCKERFILE.read_text()
    steps = _instructions(text)
    runs = " ".join(rest for word, rest in steps if word == "RUN")
    for grant in ("setcap", "chmod u+s", "chmod +s", "sudo", "gosu", "su-exec"):
        assert grant not in runs, f"a RUN step uses {grant}"
    cmd = json.loads(next(rest for word, rest in steps if word == "CMD"))
    assert int(cmd[cmd.index("--port") + 1]) >= 1024
    assert all(int(port) >= 1024 for word, rest in steps if word == "EXPOSE"
               for port in rest.split())
    run = re.search(r"docker run (.*?)roslibpy-lite-bridge\n",
                    re.sub(r"\\\n#\s*", "", text.partition("FROM")[0]), re.S)
    assert run is not None, "the header shows no docker run"
    options = run[1].split()
    assert "--cap-drop ALL" in " ".join(options), options
    assert "--security-opt no-new-privileges" in " ".join(options), options
    assert not {"--privileged", "--cap-add"} & set(options), options
