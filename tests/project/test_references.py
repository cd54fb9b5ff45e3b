"""Every module, object and file the project's text names exists.

Docstrings, comments, the spec data and the docs name modules (``manip.codecs.messages``), objects in
them (``manip.codecs.messages.encode_async``) and files (``reference_server/session.py``).  A rename
that forgets one leaves a reader looking for something that is not there, so each name is resolved
here: a dotted name whose second component is one of manip's own modules must import (its longest
importable prefix) and have the attributes that follow; a path must exist below one of :data:`ROOTS` or
a folder above the file that names it.  Dotted names under other prefixes (``manip.ChaosFrame``, a
capture schema; ``manip.capture``, a metadata key) are not module names.
"""

from __future__ import annotations

import importlib
import pkgutil
import re
from pathlib import Path

import manip
from tests.support.paths import ROOT

ROOTS = (ROOT, ROOT / "src", ROOT / "src" / "manip", ROOT / "src" / "manip" / "conformance")
"""Where the texts' relative paths start from (the repository, the source tree, the package, the suite)."""
MODULES = frozenset(info.name for info in pkgutil.iter_modules(manip.__path__))
DOTTED = re.compile(r"(?<![\w./-])manip((?:\.[A-Za-z_]\w*)+)")
PATH = re.compile(r"(?<![\w./])((?:[a-z_0-9]+/)+[a-z_0-9]+\.(?:py|toml|md|lua|json))")
# Paths a text gives as an example of a name to choose, not as a file that exists.
EXAMPLE_PATHS: frozenset[str] = frozenset()


def _texts() -> list[Path]:
    src, docs = ROOT / "src", (ROOT / "docs").glob("*.md")
    top = (ROOT / "README.md", ROOT / "CONTRIBUTING.md")
    return sorted([*src.rglob("*.py"), *src.rglob("*.toml"), *docs, *top])


def _resolves(dotted: str) -> bool:
    parts = dotted.split(".")
    for end in range(len(parts), 1, -1):
        try:
            obj: object = importlib.import_module(".".join(parts[:end]))
        except ImportError:
            continue
        for name in parts[end:]:
            if not hasattr(obj, name):
                return False
            obj = getattr(obj, name)
        return True
    return False


def test_every_dotted_module_name_resolves() -> None:
    missing: list[str] = []
    for path in _texts():
        for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
            for match in DOTTED.finditer(line):
                dotted = "manip" + match.group(1).rstrip(".")
                if dotted.split(".")[1] in MODULES and not _resolves(dotted):
                    missing.append(f"{path.relative_to(ROOT)}:{number}: {dotted}")
    assert not missing, "names of modules or objects that do not exist:\n" + "\n".join(missing)


def test_every_file_path_named_exists() -> None:
    missing: list[str] = []
    for path in _texts():
        roots = [*ROOTS, *path.parents]
        for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
            for match in PATH.finditer(line):
                named = match.group(1)
                if named not in EXAMPLE_PATHS and not any((root / named).exists() for root in roots):
                    missing.append(f"{path.relative_to(ROOT)}:{number}: {named}")
    assert not missing, "paths of files that do not exist:\n" + "\n".join(missing)


def test_the_checks_find_a_name_that_is_gone() -> None:
    assert _resolves("manip.codecs.messages.encode_async")
    assert not _resolves("manip.codecs.manip")
    assert not _resolves("manip.conformance.checks.check_transcript")


def test_the_architecture_map_names_every_package_and_top_level_module() -> None:
    """docs/architecture.md is the map a maintainer starts from: every package of ``src/manip`` (by its
    dotted name or its folder) and every module at the top of ``manip`` is on it."""
    text = (ROOT / "docs" / "architecture.md").read_text(encoding="utf-8")
    package_dir = ROOT / "src" / "manip"
    missing = []
    for init in sorted(package_dir.rglob("__init__.py")):
        folder = init.parent.relative_to(package_dir)
        if folder == Path("."):
            continue
        dotted = "manip." + ".".join(folder.parts)
        if dotted not in text and f"`{folder.as_posix()}/`" not in text and f"`{folder.name}/`" not in text:
            missing.append(dotted)
    for module in sorted(package_dir.glob("*.py")):
        if module.stem != "__init__" and f"manip.{module.stem}" not in text:
            missing.append(f"manip.{module.stem}")
    assert not missing, f"docs/architecture.md does not mention: {missing}"
