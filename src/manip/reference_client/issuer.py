"""The one primitive every operation is written with: send a request by name, return its result."""

from __future__ import annotations

import enum
from abc import ABC, abstractmethod
from collections.abc import Mapping
from typing import Any, Final, TypeVar

from manip.reference_client.request import DataExtractor

T = TypeVar("T")


class Default(enum.Enum):
    """Marks an argument left to the connection's options."""

    DEFAULT = "default"


DEFAULT: Final = Default.DEFAULT

Timeout = float | None | Default
"""Seconds, None for no limit, or DEFAULT for the connection's ``ClientOptions.timeout``."""


class RequestIssuer(ABC):
    """Operations are written against this: :class:`~manip.reference_client.manipulator.Manipulator`
    implements it with the background process."""

    @abstractmethod
    async def _call(
        self,
        code: str,
        extractor: DataExtractor[T],
        fields: Mapping[str, Any] | None = None,
        *,
        timeout: Timeout = DEFAULT,
    ) -> T:
        """Send request ``code`` with its spec layout filled from ``fields``; return what ``extractor``
        makes of the reply."""
