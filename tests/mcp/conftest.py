"""Fixtures of the MCP tests: the security tests' bridge requiring tokens and its roles."""

from __future__ import annotations

from tests.security.conftest import auth, auth_bridge

__all__ = ["auth", "auth_bridge"]
