"""The build's name checks (see :mod:`simulators.epson.spel`): every name is declared, a local
hides no global, function or #define in any case, a user function is called with its number of
arguments, ``Xqt`` starts a function without parameters, ``OnErr GoTo`` names a label of its
function, and only a variable or the function's own name is assigned."""

from __future__ import annotations

import re
from typing import Any

__all__ = ["check_names"]

#: names that read as values without parentheses
VALUE_WORDS = frozenset({"on", "off", "true", "false", "here", "tillon", "estopon", "err", "tw"})


def _walk(body: list) -> Any:
    for st in body:
        yield st
        kind = st[0]
        if kind == "if":
            for _c, b in st[1]:
                yield from _walk(b)
            yield from _walk(st[2])
        elif kind in ("for",):
            yield from _walk(st[5])
        elif kind == "do":
            yield from _walk(st[2])


def _exprs(st: Any) -> Any:
    kind = st[0]
    if kind == "assign":
        return [st[1], st[2]]
    if kind == "callstmt":
        return [st[1]]
    if kind == "if":
        return [c for c, _b in st[1]]
    if kind == "for":
        return [st[2], st[3], st[4]]
    if kind == "do":
        return [st[1]] if st[1] is not None else []
    if kind == "wait":
        return [st[1]]
    if kind == "net":
        return [st[2], *st[3]]
    if kind == "robot":
        return [a for a in st[2] if not (a[0] == "num" and isinstance(a[1], str))]
    if kind == "go":
        return [st[1]] + ([st[2]] if st[2] is not None else [])
    return []


def check_names(prog: Any, builtins: frozenset[str]) -> list[tuple[int, str]]:
    errors: list[tuple[int, str]] = []
    glob = {g[0]: g for g in prog.globals}
    for name, _t, _d, _q, line in prog.globals:
        if name in prog.functions or name in prog.defines:
            errors.append((line, f"global {name} has the name of a function or #define"))
    for fn in prog.functions.values():
        local: dict[str, tuple[str, tuple[int, ...]]] = {p: (t, ()) for p, t in fn.params}
        for st in _walk(fn.body):
            if st[0] == "decl":
                for name, dims in st[2]:
                    if name in local:
                        errors.append((st[3], f"{name} declared twice in {fn.name}"))
                    local[name] = (st[1], dims)
        for name in local:
            for other, what in ((glob, "global"), (prog.functions, "function"), (prog.defines, "#define")):
                if name in other:
                    line = next((st[3] for st in _walk(fn.body) if st[0] == "decl" and any(n == name for n, _ in st[2])), fn.line)
                    errors.append((line, f"local {name} of {fn.name} has the name of a {what} (names are not "
                                         f"case-sensitive): it would hide it"))

        def known_var(name: str, local=local, fn=fn) -> bool:
            # Pn: the controller's point variables (SPEL+ point syntax)
            return (name in local or name in glob or (name == fn.name and fn.returns is not None)
                    or re.fullmatch(r"p\d+", name) is not None)

        def expr(node: Any, line: int, local=local, fn=fn, known_var=known_var) -> None:
            kind = node[0]
            if kind == "name":
                if not (known_var(node[1]) or node[1] in VALUE_WORDS or node[1] in builtins):
                    errors.append((node[2], f"{node[1]} is not declared"))
                elif node[1] in prog.functions and node[1] != fn.name:
                    if prog.functions[node[1]].params:
                        errors.append((node[2], f"{node[1]} needs its arguments in parentheses"))
            elif kind == "call":
                name, args = node[1], node[2]
                if name in local or name in glob:
                    pass
                elif name in prog.functions:
                    callee = prog.functions[name]
                    if len(args) != len(callee.params):
                        errors.append((node[3], f"{name} takes {len(callee.params)} argument(s), given {len(args)}"))
                elif name not in builtins:
                    errors.append((node[3], f"{name} is neither declared nor a function of the subset"))
                for a in args:
                    expr(a, line)
            elif kind == "array":
                if node[1] not in local and node[1] not in glob:
                    errors.append((node[2], f"array {node[1]} is not declared"))
            elif kind in ("bin", "cmp"):
                expr(node[2], line)
                expr(node[3], line)
            elif kind in ("neg", "not", "paren"):
                expr(node[1], line)
            elif kind == "hand":
                expr(node[1], line)

        for st in _walk(fn.body):
            line = st[-1]
            for e in _exprs(st):
                expr(e, line)
            if st[0] == "assign" and st[1][0] not in ("name", "call"):
                errors.append((line, "only a variable or an array element can be assigned"))
            elif st[0] == "assign" and not known_var(st[1][1]):
                errors.append((line, f"{st[1][1]} is not a variable"))
            elif st[0] == "callstmt" and st[1][1] not in prog.functions and st[1][1] not in builtins:
                errors.append((line, f"{st[1][1]} is not a function"))
            elif st[0] == "for" and not known_var(st[1]):
                errors.append((line, f"loop variable {st[1]} is not declared"))
            elif st[0] == "xqt":
                callee = prog.functions.get(st[1])
                if callee is None or callee.params:
                    errors.append((line, f"Xqt {st[1]}: no such function without parameters"))
            elif st[0] == "onerr" and st[1] not in fn.labels:
                errors.append((line, f"OnErr GoTo {st[1]}: no such label in {fn.name}"))
    return errors
