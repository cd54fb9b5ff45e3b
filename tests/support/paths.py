"""Where things are, for tests wherever they sit in ``tests/``: the repository's root, and this folder of
helpers (scripts a test starts as a process)."""

from __future__ import annotations

from pathlib import Path

SUPPORT = Path(__file__).resolve().parent
ROOT = SUPPORT.parents[1]
