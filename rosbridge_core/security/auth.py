"""Principals and tokens: the ``--auth-file``, token checks, and the add-principal helper.

The auth file is TOML, written by hand or by the helper::

    [roles.viewer]                 # see rosbridge_core.security.permissions for the keys
    subscribe = ["*"]
    introspection = ["*"]

    [principals.alice]
    role = "viewer"
    token_hash = "sha256$<salt hex>$<digest hex>"

Tokens are 256-bit random strings made by the helper
(``roslibpy-lite-bridge add-principal alice --role viewer --auth-file auth.toml``
or ``python -m rosbridge_core.security.auth alice --role viewer --auth-file auth.toml``),
printed once and stored only as a salted SHA-256 digest. A fast hash is the
right tool for a random token of that length (a slow KDF protects guessable
passwords, and a token is not one); every principal is compared with
``hmac.compare_digest``, with no early exit, so timing tells nothing about
which digest came close. The token itself never reaches a log line or an
error text.

Failed attempts are counted per client address (:class:`FailureTracker`):
after :data:`FREE_FAILURES` failures in a row, that address is refused with
HTTP 429 (``Retry-After``) for 1 s, then 2, 4, ... up to :data:`MAX_LOCKOUT`
seconds; a success resets the count, and so do :data:`FORGET_AFTER` seconds without
a failure.
"""

from __future__ import annotations

import argparse
import contextlib
import hashlib
import hmac
import os
import pwd
import re
import secrets
import sys
import time
import tomllib
from collections import OrderedDict
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from rosbridge_core.interfaces import BridgeError
from rosbridge_core.security.accounts import CrossLimits, LimitsError, limits_from_table
from rosbridge_core.security.permissions import Role, RoleError

__all__ = [
    "AuthConfig",
    "AuthFileError",
    "FailureTracker",
    "Principal",
    "hash_token",
    "load_auth_file",
    "main",
    "new_token",
]

FREE_FAILURES = 5
"""Failed attempts from one address before it is locked out for a while."""

MAX_LOCKOUT = 60.0
"""Longest lock-out of an address, in seconds."""

FORGET_AFTER = 600.0
"""Seconds after its last failure that an address's failures are forgotten."""

EXAMPLE_ROLES = """\
# Roles: capabilities on name patterns (fnmatch globs); deny wins over allow.
# Capabilities: subscribe, publish, call_service, serve_service, send_action_goal,
# cancel_any_goal, serve_action, params, introspection, take_over; "all" grants every one.

[roles.viewer]
subscribe = ["*"]
introspection = ["*"]

[roles.operator]
subscribe = ["*"]
introspection = ["*"]
publish = ["/cmd_vel"]
call_service = ["/reset", "/dock", "/undock"]
send_action_goal = ["/navigate_to_pose"]
deny.publish = ["/rosout", "/parameter_events"]

[roles.admin]
all = ["*"]
"""


class AuthFileError(BridgeError):
    """The auth file cannot be used (the text names the file and what is wrong)."""


@dataclass(frozen=True)
class Principal:
    """A named holder of a token, with a role."""

    name: str
    role: Role
    salt: bytes = field(repr=False)  # kept out of reprs, tracebacks and logs
    digest: bytes = field(repr=False)


@dataclass
class AuthConfig:
    """What the auth file defines."""

    roles: dict[str, Role]
    principals: list[Principal]
    limits: CrossLimits = field(default_factory=CrossLimits)
    """The top-level ``[limits]``: what a principal, and an address, may hold over all
    its connections (:mod:`.accounts`)."""
    _role_of: dict[str, Role] = field(default_factory=dict, init=False, repr=False)

    def __post_init__(self) -> None:
        self._role_of = {p.name: p.role for p in self.principals}

    def limits_of(self, principal: str | None) -> tuple[Mapping[str, int], Mapping[str, int]]:
        """What ``principal`` (a name) may hold, and what an address may: its role's
        ``limits`` over the file's ``[limits.per_principal]``, and ``[limits.per_address]``."""
        mine: Mapping[str, int] = self.limits.per_principal
        role = self._role_of.get(principal) if principal is not None else None
        if role is not None and role.limits:
            mine = {**mine, **role.limits}
        return mine, self.limits.per_address

    def verify(self, token: str) -> Principal | None:
        """The principal whose token this is, or ``None`` (compares with every principal)."""
        data = token.encode("utf-8", "surrogatepass")
        found: Principal | None = None
        for p in self.principals:
            if hmac.compare_digest(hashlib.sha256(p.salt + data).digest(), p.digest):
                found = p
        return found


def new_token() -> str:
    """A fresh random token (256 bits, URL safe, so it fits in a query string), never
    starting with ``-``: given as ``--token TOKEN`` it would read as an option."""
    while (token := secrets.token_urlsafe(32)).startswith("-"):
        pass
    return token


def hash_token(token: str, salt: bytes | None = None) -> str:
    """The ``token_hash`` text stored for ``token``: ``sha256$<salt hex>$<digest hex>``."""
    salt = salt if salt is not None else secrets.token_bytes(16)
    digest = hashlib.sha256(salt + token.encode()).hexdigest()
    return f"sha256${salt.hex()}${digest}"


def _parse_hash(text: Any, where: str) -> tuple[bytes, bytes]:
    parts = text.split("$") if isinstance(text, str) else []
    if len(parts) != 3 or parts[0] != "sha256":
        raise AuthFileError(f"{where}: token_hash must look like 'sha256$<salt hex>$<digest hex>'")
    try:
        salt, digest = bytes.fromhex(parts[1]), bytes.fromhex(parts[2])
    except ValueError:
        raise AuthFileError(f"{where}: token_hash holds something that is not hex") from None
    if len(digest) != 32:
        raise AuthFileError(f"{where}: the digest of token_hash must be 32 bytes")
    return salt, digest


def load_auth_file(path: str | Path) -> AuthConfig:
    """Read and check an auth file; every problem names the file and the key."""
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        from rosbridge_core.security.options import (
            user_name,  # (the security package imports this module)
        )

        raise AuthFileError(f"cannot read {path} as user {user_name()}: {exc.strerror}") from None
    except tomllib.TOMLDecodeError as exc:
        raise AuthFileError(f"{path}: not valid TOML: {exc}") from None
    unknown = set(data) - {"roles", "principals", "limits"}
    if unknown:
        raise AuthFileError(f"{path}: unknown top-level key(s) {sorted(unknown)}")
    try:
        limits = limits_from_table(data.get("limits", {}), str(path))
    except LimitsError as exc:
        raise AuthFileError(str(exc)) from None
    roles: dict[str, Role] = {}
    for name, table in data.get("roles", {}).items():
        if not isinstance(table, dict):
            raise AuthFileError(f"{path}: roles.{name} must be a table")
        try:
            roles[name] = Role.from_table(name, table)
        except RoleError as exc:
            raise AuthFileError(f"{path}: {exc}") from None
    principals: list[Principal] = []
    for name, table in data.get("principals", {}).items():
        where = f"{path}: principals.{name}"
        if not isinstance(table, dict):
            raise AuthFileError(f"{where} must be a table")
        role_name = table.get("role")
        if role_name not in roles:
            raise AuthFileError(
                f"{where}: role {role_name!r} is not defined (roles: {', '.join(roles) or 'none'})"
            )
        salt, digest = _parse_hash(table.get("token_hash"), where)
        principals.append(Principal(name, roles[role_name], salt, digest))
    return AuthConfig(roles, principals, limits)


class FailureTracker:
    """Failed authentication attempts per address, and the lock-out they earn."""

    def __init__(self, free: int = FREE_FAILURES, max_lockout: float = MAX_LOCKOUT,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.clock = clock
        self.free = free
        self.max_lockout = max_lockout
        self._seen: OrderedDict[str, tuple[int, float]] = OrderedDict()

    def locked_for(self, address: str) -> float:
        """Seconds ``address`` must still wait (0: it may try now)."""
        entry = self._seen.get(address)
        if entry is None:
            return 0.0
        count, last = entry
        if count < self.free:
            return 0.0
        wait = min(2.0 ** (count - self.free), self.max_lockout)
        return max(0.0, last + wait - self.clock())

    def failed(self, address: str) -> int:
        """Count one failure; returns the count so far (failures long past are forgotten)."""
        now = self.clock()
        count, last = self._seen.pop(address, (0, now))
        count = 1 if now - last > FORGET_AFTER else count + 1
        self._seen[address] = (count, now)
        while len(self._seen) > 10_000:
            self._seen.popitem(last=False)
        return count

    def succeeded(self, address: str) -> None:
        """A valid token from ``address``: its failures are NOT forgotten.

        Failures are counted per address whatever succeeds in between, so a guesser who
        also holds one valid token cannot interleave logins to reset the count; they age
        out after :data:`FORGET_AFTER` seconds without a new failure.
        """


# -- the helper command ----------------------------------------------------------------------


def owner_ids(user: str) -> tuple[int, int]:
    """The uid and primary gid of ``user``: a name, or a number (a container's user, who
    may have no account here: then the group stays as it is, -1)."""
    try:
        entry = pwd.getpwuid(int(user)) if user.isdigit() else pwd.getpwnam(user)
    except KeyError:
        if user.isdigit():
            return int(user), -1
        raise AuthFileError(f"--owner {user}: no such user on this machine") from None
    return entry.pw_uid, entry.pw_gid


def add_principal(path: Path, name: str, role: str, owner: str | None = None) -> str:
    """Add principal ``name`` with ``role`` to the auth file (made with example roles if new).

    A new file is made mode 600, in a folder made mode 750 if it is missing. With ``owner``
    (the user the bridge runs as) the file becomes that user's, and a folder made here its
    group's, so the bridge can read the file and nobody else can. Returns the new token;
    only its hash is written.
    """
    if not re.fullmatch(r"[A-Za-z0-9_-]+", name):  # a TOML bare key: 'é' would break the file
        raise AuthFileError(f"principal name {name!r}: use ASCII letters, digits, '-' and '_'")
    ids = owner_ids(owner) if owner is not None else None
    if not path.parent.exists():
        path.parent.mkdir(mode=0o750, parents=True)
        if ids is not None:
            os.chown(path.parent, -1, ids[1])
    if not path.exists():
        path.write_text(EXAMPLE_ROLES, encoding="utf-8")
        path.chmod(0o600)
    if ids is not None:
        os.chown(path, *ids)
    config = load_auth_file(path)
    if role not in config.roles:
        known = ", ".join(config.roles)
        raise AuthFileError(f"{path}: role {role!r} is not defined (roles: {known})")
    if any(p.name == name for p in config.principals):
        raise AuthFileError(f"{path}: principal {name!r} exists already; remove it first")
    token = new_token()
    with path.open("a", encoding="utf-8") as f:
        f.write(f'\n[principals.{name}]\nrole = "{role}"\ntoken_hash = "{hash_token(token)}"\n')
    load_auth_file(path)  # what was written must load
    return token


def remove_principal(path: Path, name: str) -> None:
    """Remove principal ``name``'s table from the auth file (comments and the rest stay).

    A bridge running with the file drops the principal's sessions when it
    reloads it (SIGHUP).
    """
    config = load_auth_file(path)
    if not any(p.name == name for p in config.principals):
        known = ", ".join(p.name for p in config.principals) or "none"
        raise AuthFileError(f"{path}: no principal {name!r} (principals: {known})")
    header = re.compile(rf"\s*\[\s*principals\.(?:{re.escape(name)}|\"{re.escape(name)}\")\s*\]")
    kept: list[str] = []
    inside = False
    for line in path.read_text(encoding="utf-8").splitlines(keepends=True):
        if line.lstrip().startswith("["):
            inside = bool(header.match(line))
        if not inside:
            kept.append(line)
    text = "".join(kept)
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(text, encoding="utf-8")
    st = path.stat()
    tmp.chmod(st.st_mode & 0o777)
    if (st.st_uid, st.st_gid) != (os.geteuid(), os.getegid()):  # keep the bridge's ownership
        with contextlib.suppress(PermissionError):  # (only root may give a file away)
            os.chown(tmp, st.st_uid, st.st_gid)
    try:
        left = load_auth_file(tmp)
        if any(p.name == name for p in left.principals):  # e.g. written as a dotted key
            raise AuthFileError(f"{path}: principal {name!r} is not written as a "
                                f"[principals.{name}] table; remove it by hand")
    except AuthFileError:
        tmp.unlink()
        raise
    tmp.replace(path)  # atomic: a bridge reloading now reads the old file or the new one


def main(argv: list[str] | None = None) -> int:
    """``roslibpy-lite-bridge add-principal|remove-principal NAME ... --auth-file FILE``."""
    argv = sys.argv[1:] if argv is None else argv
    command = "add-principal"
    if argv[:1] in (["add-principal"], ["remove-principal"]):
        command, argv = argv[0], argv[1:]
    if command == "remove-principal":
        p = argparse.ArgumentParser(
            prog="roslibpy-lite-bridge remove-principal",
            description="Remove a principal from an auth file (then send the bridge SIGHUP "
            "to close its sessions).",
        )
        p.add_argument("name", help="principal name")
        p.add_argument("--auth-file", required=True, type=Path, help="the TOML auth file")
        args = p.parse_args(argv)
        try:
            remove_principal(args.auth_file, args.name)
        except AuthFileError as exc:
            print(f"error: {exc}", file=sys.stderr)
            return 1
        print(f"principal {args.name} removed from {args.auth_file}; a running bridge "
              "forgets it when it reloads the file (SIGHUP)", file=sys.stderr)
        return 0
    p = argparse.ArgumentParser(
        prog="roslibpy-lite-bridge add-principal",
        description="Add a principal to an auth file and print its new token (once).",
    )
    p.add_argument("name", help="principal name (ASCII letters, digits, '-', '_')")
    p.add_argument("--role", required=True, help="a role defined in the file")
    p.add_argument("--auth-file", required=True, type=Path,
                   help="the TOML auth file (created mode 600 with example roles if missing, "
                   "and its folder mode 750)")
    p.add_argument("--owner", help="the user the bridge runs as (e.g. roslibpy-bridge): the "
                   "file becomes theirs, a folder made here their group's")
    p.add_argument("--token-file", type=Path,
                   help="write the token to this new file, mode 600 (readable by you alone), "
                   "instead of printing it; refused if the file exists")
    args = p.parse_args(argv)
    if args.token_file is not None and args.token_file.exists():
        print(f"error: --token-file {args.token_file}: exists already; remove it or name "
              "another file (no principal was added)", file=sys.stderr)
        return 1
    try:
        token = add_principal(args.auth_file, args.name, args.role, args.owner)
    except AuthFileError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    except OSError as exc:  # a folder or file this user may not write
        print(f"error: {args.auth_file}: {exc.strerror or exc}", file=sys.stderr)
        return 2
    if args.token_file is None:
        print(token)
        shown = "this token is shown only now"
    else:
        try:
            write_token_file(args.token_file, token)
        except OSError as exc:  # its folder is missing or not ours: take the principal out
            remove_principal(args.auth_file, args.name)
            print(f"error: --token-file {args.token_file}: {exc.strerror or exc} (no principal "
                  "was added)", file=sys.stderr)
            return 2
        shown = f"its token is in {args.token_file} (mode 600)"
    print(f"principal {args.name} ({args.role}) added to {args.auth_file}; "
          f"{shown} (a running bridge accepts it after SIGHUP)", file=sys.stderr)
    return 0


def write_token_file(path: Path, token: str) -> None:
    """Write ``token`` to the new file ``path``, mode 600 from its creation (never readable
    by others, as ``add-principal ... > file`` under a umask of 022 leaves it)."""
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    with os.fdopen(fd, "w", encoding="utf-8") as f:
        f.write(token + "\n")

if __name__ == "__main__":
    sys.exit(main())
