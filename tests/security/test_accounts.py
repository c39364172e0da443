"""The accounts of what a principal's, and an address's, connections hold together
(rosbridge_core/security/accounts.py), and their limits in the auth file."""

from __future__ import annotations

from pathlib import Path

import pytest

from rosbridge_core.security.accounts import (
    DEFAULT_MESSAGES,
    FRAGMENT_BYTES,
    INFLIGHT_BYTES,
    Accounts,
)
from rosbridge_core.security.auth import AuthFileError, hash_token, load_auth_file

MiB = 2**20


def accounts(per_principal: dict[str, int] | None = None,
             per_address: dict[str, int] | None = None) -> Accounts:
    """Accounts with these limits for every principal and address."""
    return Accounts(lambda principal: (per_principal or {}, per_address or {}))


def test_a_principals_connections_share_its_limit_across_addresses() -> None:
    """Two connections of one principal from two addresses are held to its limit together,
    and the refusal names the principal and the per-token limit."""
    acc = accounts({FRAGMENT_BYTES: 10 * MiB})
    one, two = acc.holder("10.0.0.1"), acc.holder("10.0.0.2")
    one.become("alice")
    two.become("alice")
    assert one.take(FRAGMENT_BYTES, 6 * MiB) is None
    why = two.take(FRAGMENT_BYTES, 6 * MiB)
    assert why == ("fragment memory of principal alice's connections would pass the "
                   f"per-token limit (fragment_bytes {10 * MiB} bytes)")
    assert acc.held(FRAGMENT_BYTES, principal="alice") == 6 * MiB
    assert two.take(FRAGMENT_BYTES, 4 * MiB) is None  # what fits is still taken


def test_an_addresss_connections_share_its_limit_whoever_they_are() -> None:
    """Connections of two principals (and one of none) from one address are held to the
    address's limit together; the refusal names the address and the per-address limit."""
    acc = accounts({}, {INFLIGHT_BYTES: 8 * MiB})
    alice, bob, anyone = (acc.holder("10.0.0.9") for _ in range(3))
    alice.become("alice")
    bob.become("bob")
    assert alice.take(INFLIGHT_BYTES, 3 * MiB) is None
    assert bob.take(INFLIGHT_BYTES, 3 * MiB) is None
    assert anyone.take(INFLIGHT_BYTES, 3 * MiB) == (
        "in-flight bytes of the connections from 10.0.0.9 would pass the per-address limit "
        f"(inflight_bytes {8 * MiB} bytes)")


def test_the_default_is_a_multiple_of_the_largest_message() -> None:
    """Without a configured limit, DEFAULT_MESSAGES largest messages fit and one byte more
    does not; forced charges (data already read) make over() say so."""
    acc = accounts()
    acc.message_size = MiB
    holder = acc.holder("::1")
    assert holder.take(INFLIGHT_BYTES, DEFAULT_MESSAGES * MiB) is None
    assert holder.take(INFLIGHT_BYTES, 1) is not None
    assert holder.over(INFLIGHT_BYTES) is None
    holder.force(INFLIGHT_BYTES, 1)
    assert holder.over(INFLIGHT_BYTES) is not None


def test_closing_a_connection_releases_what_it_held() -> None:
    """A connection that ends gives back everything (moved to its principal when it proved
    one) while another of the principal's stays charged; the accounts of a principal and an
    address with no connection left are forgotten."""
    acc = accounts({FRAGMENT_BYTES: 4 * MiB})
    holder, other = acc.holder("10.0.0.1"), acc.holder("10.0.0.1")
    other.become("alice")
    other.force(FRAGMENT_BYTES, MiB)
    holder.force(FRAGMENT_BYTES, 2 * MiB)
    holder.become("alice")  # held before it proved who it is: now the principal's too
    assert acc.held(FRAGMENT_BYTES, principal="alice") == 3 * MiB
    assert holder.take(FRAGMENT_BYTES, 2 * MiB) is not None
    holder.close()
    assert acc.held(FRAGMENT_BYTES, principal="alice") == MiB
    assert acc.held(FRAGMENT_BYTES, address="10.0.0.1") == MiB
    assert other.take(FRAGMENT_BYTES, 3 * MiB) is None
    holder.give_back(FRAGMENT_BYTES, MiB)  # late give-backs of an ended connection: nothing
    assert acc.held(FRAGMENT_BYTES, address="10.0.0.1") == 4 * MiB
    other.close()
    assert not acc._principals and not acc._addresses


def _write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "auth.toml"
    path.write_text(text + f'\n[principals.p]\nrole = "r"\ntoken_hash = "{hash_token("t")}"\n')
    return path


def test_the_auth_file_sets_limits_per_principal_per_role_and_per_address(
    tmp_path: Path,
) -> None:
    """[limits.per_principal], a role's limits (winning over it) and [limits.per_address]
    are read as written."""
    config = load_auth_file(_write(tmp_path, (
        "[limits.per_principal]\nfragment_bytes = 100\ninflight_bytes = 200\n"
        "[limits.per_address]\ninflight_bytes = 0\n"
        '[roles.r]\nsubscribe = ["*"]\nlimits.inflight_bytes = 50\n')))
    assert config.limits_of("p") == ({"fragment_bytes": 100, "inflight_bytes": 50},
                                     {"inflight_bytes": 0})
    assert config.limits_of(None)[0] == {"fragment_bytes": 100, "inflight_bytes": 200}


@pytest.mark.parametrize(("text", "error"), [
    ("[limits]\nper_token = {}\n", "unknown key(s) ['per_token'] in limits"),
    ("[limits.per_address]\nfragments = 1\n", "limits.per_address: unknown limit 'fragments'"),
    ("[limits.per_principal]\nfragment_bytes = -1\n",
     "limits.per_principal.fragment_bytes must be a whole number of bytes >= 0"),
    ('[limits.per_address]\ninflight_bytes = "64MiB"\n',
     "limits.per_address.inflight_bytes must be a whole number of bytes >= 0"),
    ("[roles.r]\nlimits = 5\n", "role r: limits must be a table of fragment_bytes"),
    ("[roles.r]\nlimits.inflight_bytes = true\n",
     "role r: limits.inflight_bytes must be a whole number of bytes"),
], ids=["scope", "kind", "negative", "text", "role-not-table", "role-bool"])
def test_a_malformed_limit_names_the_file_and_the_key(tmp_path: Path, text: str,
                                                      error: str) -> None:
    """Every malformed limit is refused at load, naming the file and the key."""
    if "[roles.r]" not in text:
        text += '\n[roles.r]\nsubscribe = ["*"]\n'
    with pytest.raises(AuthFileError) as refused:
        load_auth_file(_write(tmp_path, text))
    assert str(tmp_path / "auth.toml") in str(refused.value)
    assert error in str(refused.value)
