"""The scripts of ``tools/`` as modules, for the tests that call their functions."""

from __future__ import annotations

import importlib.util
import sys
from types import ModuleType

from tests.support.paths import ROOT

TOOLS = ROOT / "tools"


def load_tool(name: str) -> ModuleType:
    """``tools/NAME.py`` loaded as module ``NAME``, as when it runs as a script: the scripts beside it
    importable (``tools/`` is on the path, after everything else), and the module registered under its
    name (its dataclasses look their module up)."""
    if str(TOOLS) not in sys.path:
        sys.path.append(str(TOOLS))
    spec = importlib.util.spec_from_file_location(name, TOOLS / f"{name}.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module
