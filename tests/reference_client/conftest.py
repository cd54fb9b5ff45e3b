"""Fixtures of the client tests: ``url``, the reference server the command tests talk to (the shared
module-scoped one of ``tests/conftest.py``; a module that needs another, such as a server with the
simulated wrist, defines its own ``url``)."""

from __future__ import annotations

import pytest


@pytest.fixture(scope="module")
def url(reference_server_url: str) -> str:
    return reference_server_url
