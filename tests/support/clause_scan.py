"""A source scan of the conformance cases: every clause a registered case can report, found statically.

Used by ``tests/conformance/test_clauses.py``.  Running every case against the reference server with each of
its faults would reach every reporting line only if some fault drove each branch, and takes minutes; the
scan reads the code instead, so it also sees the branches no run takes.

What it reads: the source of every module of :mod:`manip.conformance.cases` (the case modules and
their helpers ``_support`` and ``_live``).  For one case it starts at the case's function and follows
what the code can reach:

* definitions nested in a reachable one (inner functions, the classes a Hypothesis machine is built of);
* a name that resolves (through the case function's closure or its module) to a function or class of
  a scanned module, called or passed on (callbacks);
* ``obj.name(...)`` calls, to the definitions named ``name`` in the calling module (methods).

A *clause position* is the ``clause=`` argument of any call, or the argument a call binds to a parameter
named ``clause`` of the callee (``Evidence("x", ...)``, ``_expect_none(ctx, replies, "x", why)``).  Its
expression is resolved to clause ids: string constants; names bound in the case function's closure or
its module (``clause=clauses[0]`` of a generated case); local assignments and ``for`` targets over
literal tuples; both arms of ``a if c else b`` and ``a or b``.  A name that is a parameter of the
function holding the position makes that parameter a *clause parameter*, resolved at each call site
instead (``expect_done(ctx, answer, clause="enable-power.done", ...)``), and a default value of a
clause parameter counts too.

``something.clause`` whose ``something`` is not resolvable is a *relay*: a finding passed on from where
it was made (``ctx.fail(clause=failure.clause, ...)``).  Relays are not counted: what they pass on is
counted where it is built (an ``Evidence(...)`` in a case module), or comes from a closed set checked
elsewhere (the checkers: :data:`manip.conformance.judge.checks.TRANSCRIPT_CLAUSES`; the stateful model:
:data:`manip.conformance.judge.model.MODEL_CLAUSES`).  Any other expression (an f-string, a call) is
*unresolved* and reported, so the scan cannot silently miss a position.
"""

from __future__ import annotations

import ast
import importlib
import inspect
import pkgutil
import sys
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from types import FunctionType, ModuleType
from typing import Any

import manip.conformance.cases as cases_package
from manip.conformance.suite.case import Case

FunctionNode = ast.FunctionDef | ast.AsyncFunctionDef
DefNode = FunctionNode | ast.ClassDef


@dataclass
class Scan:
    """What one case can report."""

    clauses: dict[str, list[str]] = field(default_factory=dict)
    """Clause id -> where (module:line) a position names it."""
    unresolved: list[str] = field(default_factory=list)
    """Positions whose expression the scan could not resolve."""

    def add(self, clause: str, where: str) -> None:
        self.clauses.setdefault(clause, []).append(where)


@dataclass
class _Def:
    module: ModuleType
    node: DefNode
    parent: _Def | None
    children: list[_Def] = field(default_factory=list)

    @property
    def name(self) -> str:
        return self.node.name

    def params(self) -> list[str]:
        if isinstance(self.node, ast.ClassDef):
            return []
        a = self.node.args
        return [p.arg for p in [*a.posonlyargs, *a.args, *a.kwonlyargs]]

    def where(self, node: ast.AST) -> str:
        return f"{self.module.__name__}:{getattr(node, 'lineno', '?')}"


def _case_modules() -> list[ModuleType]:
    out = []
    for info in pkgutil.walk_packages(cases_package.__path__, prefix=f"{cases_package.__name__}."):
        out.append(importlib.import_module(info.name))
    return out


class Index:
    """Every definition of the scanned modules, by module and by name."""

    def __init__(self, modules: list[ModuleType] | None = None) -> None:
        self.modules = modules if modules is not None else _case_modules()
        self.defs: list[_Def] = []
        self.by_module_name: dict[tuple[str, str], list[_Def]] = {}
        self.by_line: dict[tuple[str, int], _Def] = {}
        for module in self.modules:
            tree = ast.parse(inspect.getsource(module))
            self._collect(module, tree, None)

    def _collect(self, module: ModuleType, node: ast.AST, parent: _Def | None) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef):
                item = _Def(module, child, parent)
                self.defs.append(item)
                if parent is not None:
                    parent.children.append(item)
                self.by_module_name.setdefault((module.__name__, child.name), []).append(item)
                first = min([child.lineno, *(d.lineno for d in child.decorator_list)])
                for line in range(first, child.lineno + 1):
                    self.by_line[(module.__name__, line)] = item
                self._collect(module, child, item)
            else:
                self._collect(module, child, parent)

    def of_object(self, obj: object) -> _Def | None:
        """The definition of a function or class of a scanned module."""
        target = inspect.unwrap(obj) if callable(obj) else obj  # type: ignore[arg-type]
        module = sys.modules.get(getattr(target, "__module__", "") or "")
        if module is None or module not in self.modules:
            return None
        if isinstance(target, FunctionType):
            return self.by_line.get((module.__name__, target.__code__.co_firstlineno))
        if isinstance(target, type):
            found = self.by_module_name.get((module.__name__, target.__name__), [])
            return found[0] if found else None
        return None


_UNRESOLVED = object()


class Scanner:
    """Resolves the clause positions reachable from each case (see the module docstring)."""

    def __init__(self, index: Index | None = None) -> None:
        self.index = index or Index()
        self._clause_param_cache: dict[int, set[str]] = {}
        self._root: _Def | None = None

    # ------------------------------------------------------------------------------------ per case
    def scan(self, item: Case) -> Scan:
        root = self.index.of_object(item.function)
        if root is None:
            raise LookupError(f"case {item.id}: its function's source was not found")
        closure = dict(inspect.getclosurevars(item.function).nonlocals)
        self._root = root
        result = Scan()
        reachable = self._reachable(root, closure)
        for d in reachable:
            env = self._env(d, root, closure)
            for expr, where in self._positions(d, env):
                self._resolve_into(expr, d, env, reachable, result, where)
        return result

    def _env(self, d: _Def, root: _Def, closure: Mapping[str, Any]) -> dict[str, Any]:
        env = dict(vars(d.module))
        if self._inside(d, root):
            env.update(closure)
        return env

    @staticmethod
    def _inside(d: _Def, root: _Def) -> bool:
        node: _Def | None = d
        while node is not None:
            if node is root:
                return True
            node = node.parent
        return False

    def _reachable(self, root: _Def, closure: Mapping[str, Any]) -> list[_Def]:
        seen: dict[int, _Def] = {}
        todo = [root]
        while todo:
            d = todo.pop()
            if id(d) in seen:
                continue
            seen[id(d)] = d
            todo += d.children
            env = self._env(d, root, closure)
            for node in _own_nodes(d.node):
                if isinstance(node, ast.Name) and isinstance(node.ctx, ast.Load):
                    todo += self._named(d, node.id, env)
                elif isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute):
                    todo += self.index.by_module_name.get((d.module.__name__, node.func.attr), [])
        return list(seen.values())

    def _named(self, d: _Def, name: str, env: Mapping[str, Any]) -> list[_Def]:
        """Definitions a name in ``d`` refers to: a definition nested in an enclosing one, or an
        object of a scanned module."""
        scope: _Def | None = d
        while scope is not None:
            local = [c for c in scope.children if c.name == name]
            if local:
                return local
            scope = scope.parent
        if name in env:
            found = self.index.of_object(env[name])
            return [found] if found is not None else []
        return []

    # ------------------------------------------------------------------------------------ positions
    def _positions(self, d: _Def, env: Mapping[str, Any]) -> Iterator[tuple[ast.expr, str]]:
        """(expression, where) of every clause position in ``d``'s own code."""
        for node in _own_nodes(d.node):
            if isinstance(node, ast.Call):
                for expr in self._call_positions(d, node, env):
                    yield expr, d.where(expr)
        if isinstance(d.node, ast.ClassDef):
            return
        defaults = _param_defaults(d.node)
        for name in self._clause_params(d):
            if name in defaults:
                yield defaults[name], d.where(defaults[name])

    def _call_positions(self, d: _Def, call: ast.Call, env: Mapping[str, Any]) -> list[ast.expr]:
        """The ``clause=`` argument, and arguments bound to a clause parameter of a callee; none for a
        call that attributes its clause to a suite invariant (``invariant=`` given)."""
        if any(kw.arg == "invariant" and _evaluate(kw.value, env) is not None for kw in call.keywords):
            return []
        out = [kw.value for kw in call.keywords if kw.arg == "clause"]
        for params, wanted, method in self._callees(d, call, env):
            positional = params[1:] if method and params and params[0] in ("self", "cls") else params
            for index, arg in enumerate(call.args):
                if isinstance(arg, ast.Starred):
                    break
                if index < len(positional) and positional[index] in wanted:
                    out.append(arg)
            out += [kw.value for kw in call.keywords if kw.arg != "clause" and kw.arg in wanted]
        return out

    def _callees(
        self, d: _Def, call: ast.Call, env: Mapping[str, Any]
    ) -> list[tuple[list[str], set[str], bool]]:
        """(parameters, clause parameters, called as a method) of what a call may call."""
        func = call.func
        out: list[tuple[list[str], set[str], bool]] = []
        if isinstance(func, ast.Name):
            defs = self._named(d, func.id, env)
            for target in defs:
                params = self._signature_of_def(target)
                out.append((params, self._clause_params(target) | ({"clause"} & set(params)), False))
            if not defs and func.id in env:
                params = _signature_params(env[func.id]) or []
                out.append((params, {"clause"} & set(params), False))
        elif isinstance(func, ast.Attribute):
            for target in self.index.by_module_name.get((d.module.__name__, func.attr), []):
                if not isinstance(target.node, ast.ClassDef):
                    params = target.params()
                    out.append((params, self._clause_params(target) | ({"clause"} & set(params)), True))
        return out

    def _signature_of_def(self, d: _Def) -> list[str]:
        if isinstance(d.node, ast.ClassDef):
            obj = vars(d.module).get(d.name)
            return (_signature_params(obj) if obj is not None else None) or []
        return d.params()

    def _clause_params(self, d: _Def) -> set[str]:
        """Parameters of ``d`` whose value reaches a clause position (followed through calls)."""
        if id(d) in self._clause_param_cache:
            return self._clause_param_cache[id(d)]
        self._clause_param_cache[id(d)] = set()  # recursion guard
        params = set(d.params()) - {"self", "cls"}
        found: set[str] = set()
        env = vars(d.module)
        for node in _own_nodes(d.node):
            if isinstance(node, ast.Call):
                for expr in self._call_positions(d, node, env):
                    found |= _direct_names(expr) & params
        self._clause_param_cache[id(d)] = found
        return found

    # ------------------------------------------------------------------------------------ resolving
    def _resolve_into(
        self, expr: ast.expr, d: _Def, env: Mapping[str, Any], reachable: list[_Def], out: Scan, where: str
    ) -> None:
        for value in self._values(expr, d, env, depth=0):
            if value is _UNRESOLVED:
                out.unresolved.append(f"{where}: {ast.unparse(expr)}")
            elif value is None:
                continue  # a relay, or a parameter resolved at its call sites
            else:
                out.add(str(value), where)

    def _values(self, expr: ast.expr, d: _Def, env: Mapping[str, Any], depth: int) -> list[object]:
        if depth > 8:
            return [_UNRESOLVED]
        if isinstance(expr, ast.Constant):
            return (
                [expr.value]
                if isinstance(expr.value, str)
                else [None]
                if expr.value is None
                else [_UNRESOLVED]
            )
        if isinstance(expr, ast.IfExp):
            return self._values(expr.body, d, env, depth + 1) + self._values(expr.orelse, d, env, depth + 1)
        if isinstance(expr, ast.BoolOp):
            return [v for e in expr.values for v in self._values(e, d, env, depth + 1)]
        if isinstance(expr, ast.Name):
            return self._name_values(expr.id, d, env, depth)
        if isinstance(expr, ast.Attribute) and expr.attr == "clause":
            value = _evaluate(expr, env)
            return [None] if value is _UNRESOLVED else [value]
        if isinstance(expr, ast.Subscript):
            table = _evaluate(expr.value, env)
            if isinstance(table, Mapping):
                key = _evaluate(expr.slice, env)
                if key is _UNRESOLVED:
                    # a table looked up by a value known only at run time: any of its values
                    return [v if isinstance(v, str) else _UNRESOLVED for v in table.values()]
                if key not in table:
                    return [None]  # the lookup raises: the position never reports for this case
        value = _evaluate(expr, env)
        if isinstance(value, str):
            return [value]
        return [_UNRESOLVED]

    def _name_values(self, name: str, d: _Def, env: Mapping[str, Any], depth: int) -> list[object]:
        scope: _Def | None = d
        # Scopes from ``d`` up to the case function; above it, names are the closure's values (a factory's
        # parameters, for a generated case), found in ``env``.
        outer = self._root.parent if self._root is not None and self._inside(d, self._root) else None
        while scope is not None and scope is not outer:
            if name in scope.params():
                return [None]  # a clause parameter: counted at the call sites
            assigned = _assignments(scope.node, name)
            if assigned:
                return [v for e in assigned for v in self._values(e, scope, env, depth + 1)]
            looped = _loop_values(scope.node, name, env)
            if looped is not None:
                return looped
            scope = scope.parent
        if name in env:
            value = env[name]
            return [value] if isinstance(value, str) else [_UNRESOLVED]
        return [_UNRESOLVED]


def _own_nodes(node: DefNode) -> Iterator[ast.AST]:
    """The nodes of a definition, without those of definitions nested in it."""
    nested = (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)
    todo: list[ast.AST] = [n for n in node.body if not isinstance(n, nested)]
    if not isinstance(node, ast.ClassDef):
        todo += [*node.args.defaults, *(d for d in node.args.kw_defaults if d is not None)]
    todo += node.decorator_list
    while todo:
        current = todo.pop()
        yield current
        for child in ast.iter_child_nodes(current):
            if not isinstance(child, nested):
                todo.append(child)


def _direct_names(expr: ast.expr) -> set[str]:
    """Names whose value may be the expression's value (``x``, ``x if c else y``, ``x or y``)."""
    if isinstance(expr, ast.Name):
        return {expr.id}
    if isinstance(expr, ast.IfExp):
        return _direct_names(expr.body) | _direct_names(expr.orelse)
    if isinstance(expr, ast.BoolOp):
        return {n for e in expr.values for n in _direct_names(e)}
    return set()


def _param_defaults(node: FunctionNode) -> dict[str, ast.expr]:
    a = node.args
    positional = [*a.posonlyargs, *a.args]
    out = {p.arg: d for p, d in zip(positional[len(positional) - len(a.defaults) :], a.defaults, strict=True)}
    out |= {p.arg: d for p, d in zip(a.kwonlyargs, a.kw_defaults, strict=True) if d is not None}
    return out


def _assignments(node: DefNode, name: str) -> list[ast.expr]:
    out: list[ast.expr] = []
    for child in _own_nodes(node):
        if isinstance(child, ast.Assign):
            if any(isinstance(t, ast.Name) and t.id == name for t in child.targets):
                out.append(child.value)
        elif (
            isinstance(child, ast.AnnAssign)
            and isinstance(child.target, ast.Name)
            and child.target.id == name
            and child.value is not None
        ):
            out.append(child.value)
    return out


def _loop_values(node: DefNode, name: str, env: Mapping[str, Any]) -> list[object] | None:
    """Values ``name`` takes as a ``for`` target over a resolvable iterable (None: not a loop target)."""
    for child in _own_nodes(node):
        if not isinstance(child, ast.For | ast.AsyncFor | ast.comprehension):
            continue
        target = child.target
        position: int | None
        if isinstance(target, ast.Name) and target.id == name:
            position = None
        elif isinstance(target, ast.Tuple) and any(
            isinstance(e, ast.Name) and e.id == name for e in target.elts
        ):
            position = next(i for i, e in enumerate(target.elts) if isinstance(e, ast.Name) and e.id == name)
        else:
            continue
        iterable = _evaluate(child.iter, env)
        if iterable is _UNRESOLVED or not isinstance(iterable, list | tuple | set | frozenset | dict):
            return [_UNRESOLVED]
        values: list[object] = []
        for item in iterable:
            value = item if position is None else item[position]
            values.append(value if isinstance(value, str) else _UNRESOLVED)
        return values
    return None


def _evaluate(expr: ast.expr, env: Mapping[str, Any]) -> object:
    """The value of an expression made of names, attributes, subscripts and literals (no calls)."""
    if any(isinstance(n, ast.Call | ast.Lambda | ast.NamedExpr | ast.Await) for n in ast.walk(expr)):
        return _UNRESOLVED
    try:
        code = compile(ast.Expression(expr), "<clause>", "eval")
        return eval(code, {"__builtins__": {}}, dict(env))
    except Exception:
        return _UNRESOLVED


def _signature_params(obj: object) -> list[str] | None:
    if not callable(obj):
        return None
    try:
        signature = inspect.signature(obj)
    except (TypeError, ValueError):
        return None
    return list(signature.parameters)


def scan_all(cases: list[Case], scanner: Scanner | None = None) -> dict[str, Scan]:
    """The scan of every case, by id."""
    scanner = scanner or Scanner()
    return {item.id: scanner.scan(item) for item in cases}
