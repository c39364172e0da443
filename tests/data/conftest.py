"""Fixtures of the data tests: a client on the session's bridge, as the client tests have."""

from tests.client.test_bridge_formats import client  # noqa: F401 (a fixture)
