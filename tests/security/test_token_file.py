"""add-principal --token-file writes the new token to a file only its owner reads (issue 50,
item 4): ``add-principal ... > agent.token`` under a umask of 022 left it readable by all."""

from __future__ import annotations

import os
import stat
from collections.abc import Iterator
from pathlib import Path

import pytest

from rosbridge_core.security.auth import load_auth_file, main


@pytest.fixture
def umask_022() -> Iterator[None]:
    """The usual umask, under which a shell's ``> file`` makes a file mode 644."""
    old = os.umask(0o022)
    yield
    os.umask(old)


def test_token_file_is_mode_600_and_holds_the_token(
        tmp_path: Path, umask_022: None, capsys: pytest.CaptureFixture[str]) -> None:
    """The token file is mode 600, holds the one token the auth file accepts, and nothing prints it."""
    auth, token_file = tmp_path / "auth.toml", tmp_path / "agent.token"
    assert main(["add-principal", "agent", "--role", "operator", "--auth-file", str(auth),
                 "--token-file", str(token_file)]) == 0
    assert stat.S_IMODE(token_file.stat().st_mode) == 0o600
    token = token_file.read_text().strip()
    principal = load_auth_file(auth).verify(token)
    assert principal is not None and principal.name == "agent"
    out = capsys.readouterr()
    assert token not in out.out + out.err and str(token_file) in out.err, out


def test_an_existing_token_file_is_refused_before_anything_is_added(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """An existing --token-file is named in the error, kept as it was, and no principal is added."""
    auth, token_file = tmp_path / "auth.toml", tmp_path / "agent.token"
    token_file.write_text("mine\n")
    assert main(["add-principal", "agent", "--role", "viewer", "--auth-file", str(auth),
                 "--token-file", str(token_file)]) == 1
    assert token_file.read_text() == "mine\n"
    assert f"--token-file {token_file}: exists already" in capsys.readouterr().err
    assert not auth.exists()


def test_a_token_file_that_cannot_be_written_adds_no_principal(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A --token-file in a missing folder is an error naming it, and the principal is taken out again."""
    auth, token_file = tmp_path / "auth.toml", tmp_path / "missing" / "agent.token"
    assert main(["add-principal", "agent", "--role", "viewer", "--auth-file", str(auth),
                 "--token-file", str(token_file)]) == 2
    assert f"--token-file {token_file}" in capsys.readouterr().err
    assert [p.name for p in load_auth_file(auth).principals] == []
