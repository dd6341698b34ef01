"""Evaluator and thread scheduler of the URScript subset.

Semantics, each from a page of UR's e-Series Script Directory (SW 5.x) that was read:

* §9 "Scoping rules": a program is a function without parameters; a variable declared inside a
  function with ``local`` is local, with ``global`` global; a free variable (no qualifier) is
  the global of that name if one exists, else local; variables on the first scope level of the
  program are global "even if ... the local qualifier is used". This executor binds statically
  and pessimistically: every name assigned anywhere in the program function's own body (not in
  its nested functions) is global, as is every name declared ``global`` anywhere.
* §10 "Threads": ``thread name(): ... end`` takes no parameters; ``h = run name()`` starts it
  and returns a handle; ``kill h`` "stops the running thread and invalidates its handle" (and
  its children); ``join h`` waits for it. Killing a thread that already finished is refused
  here: §10 describes killing a running thread only. §10.1: threads follow the scope rules of
  functions.
* §10.2 "Thread scheduling": the controller runs in frames of 0.002 s; every runnable thread
  gets a slice of each frame; a thread that uses up its slice "either by use of physical time
  or by computational heavy instructions" is not runnable until the next frame; ``sleep`` and
  ``sync`` use physical time. How many statements fit into one slice UR does not publish: here
  it is the parameter ``budget`` (statements per thread per frame, see ``DEFAULT_BUDGET`` in
  :mod:`simulators.urscript`); a thread that reaches it is preempted - at any statement, in the
  middle of a computation - and continues in the next frame.

Anything the subset does not know stops the program with :class:`URScriptError`, as a
controller shows a runtime exception: an unknown function, an undefined name, a wrong type
(arithmetic on a bool, a non-bool condition, comparing a number with a list), an index outside a
list, an integer result outside the signed 32-bit range, and ``int / int`` (the pages read do
not say whether it truncates; the program divides floats only).
"""

from __future__ import annotations

from collections.abc import Callable, Generator, Iterator
from dataclasses import dataclass
from typing import Any

from simulators.urscript.parser import FuncDef, Node, parse

__all__ = ["URScriptError", "Program", "Builtin", "Pose", "FRAME_S", "check_int"]

#: the frame of §10.2: 0.002 s
FRAME_S = 0.002
_I32 = (-2 ** 31, 2 ** 31 - 1)


class URScriptError(Exception):
    """A runtime exception: the controller stops the program."""


class Pose(tuple):
    """A pose ``p[x, y, z, rx, ry, rz]`` (m, rotation vector)."""


@dataclass
class Builtin:
    """A built-in function: ``fn(program, *args, **kwargs)``; a ``blocking`` one returns a
    generator that yields wait commands (it takes physical time)."""

    fn: Callable[..., Any]
    blocking: bool = False
    section: str = ""


class _Return(Exception):
    def __init__(self, value: Any):
        self.value = value


class _Break(Exception):
    pass


class _Continue(Exception):
    pass


class _Thread:
    def __init__(self, name: str, parent: "_Thread | None"):
        self.name = name
        self.parent = parent
        self.gen: Iterator[Any] | None = None
        self.alive = True
        self.wait: tuple[str, Any] | None = None
        self.statements = 0

    def __repr__(self) -> str:
        return f"<thread {self.name}>"


class _Frame:
    __slots__ = ("loc", "local_names")

    def __init__(self, loc: dict[str, Any] | None, local_names: frozenset[str]):
        self.loc = loc
        self.local_names = local_names


def check_int(v: int, line: int | str = "?") -> int:
    if not _I32[0] <= v <= _I32[1]:
        raise URScriptError(f"line {line}: integer {v} outside the signed 32-bit range")
    return v


def _is_num(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _kind(v: Any) -> str:
    if isinstance(v, bool):
        return "bool"
    if _is_num(v):
        return "number"
    if isinstance(v, Pose):
        return "pose"
    if isinstance(v, list):
        return "list"
    if isinstance(v, str):
        return "string"
    return type(v).__name__


def _walk(stmts: list[Node]) -> Iterator[Node]:
    """Every statement of ``stmts``, nested blocks included, nested functions excluded."""
    for s in stmts:
        yield s
        if s.kind == "while":
            yield from _walk(s.b)
        elif s.kind == "if":
            for _cond, body in s.a:
                yield from _walk(body)
            yield from _walk(s.b)


class Program:
    """A parsed program and its threads; :meth:`step_frame` runs one 2 ms frame."""

    def __init__(self, source: str, builtins: dict[str, Builtin], budget: int, on_frame: Callable[[float], None] | None = None):
        if budget < 1:
            raise ValueError("the statement budget per frame must be at least 1")
        self.budget_per_frame = int(budget)
        self.builtins = builtins
        self.on_frame = on_frame
        self.top = parse(source)
        self.funcs: dict[str, FuncDef] = {}
        self.globals: dict[str, Any] = {}
        self.global_names: set[str] = set()
        self._analyse()
        self.time = 0.0
        self.frames = 0
        self.statements = 0
        self.error: URScriptError | None = None
        self.threads: list[_Thread] = []
        self._budget = 0
        self._current: _Thread | None = None
        root = _Thread("<program>", None)
        root.gen = self._exec_block(self.top, _Frame(None, frozenset()))
        self.threads.append(root)
        self._pending: list[_Thread] = []

    # ------------------------------------------------------------------ static scope (§9)
    def _analyse(self) -> None:
        defs: list[FuncDef] = []

        def collect(stmts: list[Node]) -> None:
            for s in _walk(stmts):
                if s.kind == "def":
                    f: FuncDef = s.a
                    if f.name in self.funcs:
                        raise URScriptError(f"line {f.line}: {f.name} defined twice")
                    self.funcs[f.name] = f
                    defs.append(f)
                    collect(f.body)

        collect(self.top)
        programs = {s.a.name for s in self.top if s.kind == "def"}
        for s in _walk(self.top):
            if s.kind == "assign" and s.a.kind == "name":
                self.global_names.add(s.a.a)
        for f in defs:
            for s in _walk(f.body):
                if s.kind == "assign" and s.a.kind == "name":
                    if s.c == "global" or (f.name in programs):
                        self.global_names.add(s.a.a)
        for f in defs:
            if f.name in programs:
                continue
            names = {p for p, _d in f.params}
            for s in _walk(f.body):
                if s.kind == "assign" and s.a.kind == "name":
                    if s.c == "local" or (s.c is None and s.a.a not in self.global_names):
                        names.add(s.a.a)
            f.locals_declared = names
        for name in programs:
            self.funcs[name].locals_declared = set()

    # ------------------------------------------------------------------ the scheduler (§10.2)
    @property
    def running(self) -> bool:
        return self.error is None and any(t.alive for t in self.threads)

    def step_frame(self) -> None:
        """One frame: every runnable thread runs until it uses up its slice (sync, sleep, a
        motion, or ``budget`` statements), then the robot moves by one frame."""
        if self.error is not None:
            return
        self.threads.extend(self._pending)
        self._pending.clear()
        for t in list(self.threads):
            if not t.alive:
                continue
            if t.wait is not None:
                kind, arg = t.wait
                if kind == "sleep" and self.time < arg - 1e-9:
                    continue
                if kind == "until" and not arg():
                    continue
                t.wait = None
            self._budget = self.budget_per_frame
            self._current = t
            try:
                assert t.gen is not None
                cmd = next(t.gen)
            except StopIteration:
                t.alive = False
                continue
            except URScriptError as exc:
                self._fail(exc)
                return
            except (_Break, _Continue, _Return) as exc:
                self._fail(URScriptError(f"{type(exc).__name__[1:].lower()} outside a loop or function"))
                return
            except (ValueError, ArithmeticError) as exc:  # a built-in refused its arguments
                self._fail(URScriptError(f"{t.name}: {exc}"))
                return
            if cmd[0] in ("sleep", "until"):
                t.wait = cmd
        self.threads = [t for t in self.threads if t.alive]
        self._current = None
        if self.on_frame is not None:
            self.on_frame(FRAME_S)
        self.time += FRAME_S
        self.frames += 1

    def _fail(self, exc: URScriptError) -> None:
        self.error = exc
        for t in self.threads + self._pending:
            t.alive = False

    # ------------------------------------------------------------------ statements
    def _exec_block(self, stmts: list[Node], fr: _Frame) -> Generator[Any, None, None]:
        for s in stmts:
            self._budget -= 1
            if self._budget < 0:
                yield ("budget",)
                self._budget -= 1  # the statement runs in the new frame, on its budget
            self.statements += 1
            if self._current is not None:
                self._current.statements += 1
            try:
                yield from self._exec(s, fr)
            except URScriptError as exc:
                if str(exc).startswith("line "):
                    raise
                raise URScriptError(f"line {s.line}: {exc}") from None

    def _exec(self, s: Node, fr: _Frame) -> Generator[Any, None, None]:
        k = s.kind
        if k == "assign":
            value = (yield from self._eval(s.b, fr)) if not s.b.pure else self._pure(s.b, fr)
            yield from self._assign(s, value, fr)
        elif k == "expr":
            if s.a.pure:
                self._pure(s.a, fr)
            else:
                yield from self._eval(s.a, fr)
        elif k == "if":
            for cond, body in s.a:
                if self._truth((yield from self._eval(cond, fr)), s.line):
                    yield from self._exec_block(body, fr)
                    return
            yield from self._exec_block(s.b, fr)
        elif k == "while":
            while True:
                if not self._truth((yield from self._eval(s.a, fr)), s.line):
                    return
                try:
                    yield from self._exec_block(s.b, fr)
                except _Break:
                    return
                except _Continue:
                    pass  # `continue` ends this pass of the body: the condition is evaluated again
                self._budget -= 1  # the condition is evaluated again: one statement
                if self._budget < 0:
                    yield ("budget",)
                    self._budget -= 1
                self.statements += 1
        elif k == "return":
            raise _Return(None if s.a is None else (yield from self._eval(s.a, fr)))
        elif k == "def":
            return  # functions are bound at parse time (their names are global)
        elif k == "kill":
            self._kill((yield from self._eval(s.a, fr)))
        elif k == "join":
            h = yield from self._eval(s.a, fr)
            if not isinstance(h, _Thread):
                raise URScriptError("join of something that is not a thread handle")
            if h.alive:
                yield ("until", lambda: not h.alive)
        elif k == "break":
            raise _Break()
        elif k == "continue":
            raise _Continue()
        else:  # pragma: no cover - the parser makes no other statement
            raise URScriptError(f"unknown statement {k}")

    def _assign(self, s: Node, value: Any, fr: _Frame) -> Generator[Any, None, None]:
        target = s.a
        if isinstance(value, list):
            value = list(value)
        if target.kind == "name":
            name = target.a
            if s.c == "global" or fr.loc is None:
                self.globals[name] = value
            elif s.c == "local" or name in fr.local_names:
                fr.loc[name] = value
            else:
                self.globals[name] = value
            return
        # target[index] = value
        container = target.a
        if container.kind != "name":
            raise URScriptError("only a list variable can be assigned by index")
        lst = self._lookup(container.a, fr)
        idx = (yield from self._eval(target.b, fr))
        self._check_index(lst, idx, list)
        lst[idx] = value

    def _kill(self, h: Any) -> None:
        if not isinstance(h, _Thread):
            raise URScriptError("kill of something that is not a thread handle")
        if not h.alive:
            raise URScriptError(f"kill of {h.name}, which is no longer running (§10 kills a running thread)")
        for t in self.threads + self._pending:
            p: _Thread | None = t
            while p is not None:
                if p is h:
                    t.alive = False
                    break
                p = p.parent

    @staticmethod
    def _truth(v: Any, line: int) -> bool:
        if not isinstance(v, bool):
            raise URScriptError(f"line {line}: a condition must be a bool, got {_kind(v)}")
        return v

    # ------------------------------------------------------------------ expressions
    def _lookup(self, name: str, fr: _Frame) -> Any:
        if fr.loc is not None and name in fr.loc:
            return fr.loc[name]
        if fr.loc is not None and name in fr.local_names:
            raise URScriptError(f"local variable {name} used before it is assigned")
        try:
            return self.globals[name]
        except KeyError:
            raise URScriptError(f"undefined name {name}") from None

    @staticmethod
    def _check_index(obj: Any, idx: Any, types: type | tuple[type, ...]) -> None:
        if not isinstance(obj, types):
            raise URScriptError(f"cannot index a {_kind(obj)}")
        if not isinstance(idx, int) or isinstance(idx, bool):
            raise URScriptError(f"an index must be an integer, got {_kind(idx)}")
        n = len(obj)  # type: ignore[arg-type]
        if not 0 <= idx < n:
            raise URScriptError(f"index {idx} outside a list of {n}")

    def _pure(self, e: Node, fr: _Frame) -> Any:
        """Evaluate an expression that runs no statements and takes no time."""
        gen = self._eval(e, fr)
        try:
            next(gen)
        except StopIteration as stop:
            return stop.value
        raise URScriptError("internal: a pure expression yielded")  # pragma: no cover

    def _eval(self, e: Node, fr: _Frame) -> Generator[Any, None, Any]:
        k = e.kind
        if k == "const":
            return e.a
        if k == "name":
            v = self._lookup(e.a, fr)
            return list(v) if isinstance(v, list) else v
        if k == "index":
            obj = self._lookup(e.a.a, fr) if e.a.kind == "name" else (yield from self._eval(e.a, fr))
            idx = yield from self._eval(e.b, fr)
            self._check_index(obj, idx, (list, Pose))
            v = obj[idx]
            return list(v) if isinstance(v, list) else v
        if k == "bin":
            a = yield from self._eval(e.b, fr)
            b = yield from self._eval(e.c, fr)
            return self._binary(e.a, a, b, e.line)
        if k == "bool":
            a = yield from self._eval(e.b, fr)
            self._truth(a, e.line)
            if (e.a == "and" and not a) or (e.a == "or" and a):
                return a
            b = yield from self._eval(e.c, fr)
            return self._truth(b, e.line)
        if k == "unary":
            v = yield from self._eval(e.b, fr)
            if e.a == "not":
                return not self._truth(v, e.line)
            if not _is_num(v):
                raise URScriptError(f"line {e.line}: unary minus of a {_kind(v)}")
            return check_int(-v, e.line) if isinstance(v, int) else -v
        if k == "list":
            out = []
            for item in e.a:
                out.append((yield from self._eval(item, fr)))
            return out
        if k == "pose":
            vals = []
            for item in e.a:
                vals.append((yield from self._eval(item, fr)))
            if len(vals) != 6 or not all(_is_num(v) for v in vals):
                raise URScriptError(f"line {e.line}: a pose is p[x, y, z, rx, ry, rz] of six numbers")
            return Pose(float(v) for v in vals)
        if k == "call":
            return (yield from self._call(e, fr))
        if k == "run":
            return self._run(e)
        if k == "attr":
            raise URScriptError(f"line {e.line}: struct members are not used by this subset")
        raise URScriptError(f"line {e.line}: unknown expression {k}")  # pragma: no cover

    @staticmethod
    def _binary(op: str, a: Any, b: Any, line: int) -> Any:
        if op in ("==", "!="):
            ka, kb = _kind(a), _kind(b)
            if ka != kb:
                raise URScriptError(f"line {line}: comparing a {ka} with a {kb}")
            return (a == b) if op == "==" else (a != b)
        if not (_is_num(a) and _is_num(b)):
            raise URScriptError(f"line {line}: {op} of a {_kind(a)} and a {_kind(b)}")
        if op == "<":
            return a < b
        if op == "<=":
            return a <= b
        if op == ">":
            return a > b
        if op == ">=":
            return a >= b
        both_int = isinstance(a, int) and isinstance(b, int)
        if op == "/":
            if both_int:
                raise URScriptError(f"line {line}: int / int: the Script Directory pages read do not say whether "
                                    f"it truncates; divide by a float")
            if b == 0:
                raise URScriptError(f"line {line}: division by zero")
            return a / b
        r = a + b if op == "+" else a - b if op == "-" else a * b
        return check_int(r, line) if both_int else float(r)

    def _run(self, e: Node) -> _Thread:
        f = self.funcs.get(e.a)
        if f is None or not f.is_thread:
            raise URScriptError(f"line {e.line}: run {e.a}(): no thread of that name")
        t = _Thread(f.name, self._current)
        t.gen = self._thread_body(f)
        self._pending.append(t)
        return t

    def _thread_body(self, f: FuncDef) -> Generator[Any, None, None]:
        try:
            yield from self._exec_block(f.body, _Frame({}, frozenset(f.locals_declared)))
        except _Return:
            return

    def _call(self, e: Node, fr: _Frame) -> Generator[Any, None, Any]:
        name = e.a
        args = []
        for a in e.b:
            args.append((yield from self._eval(a, fr)))
        kwargs = {}
        for key, a in e.c.items():
            kwargs[key] = yield from self._eval(a, fr)
        f = self.funcs.get(name)
        if f is not None:
            if f.is_thread:
                raise URScriptError(f"line {e.line}: {name} is a thread: start it with run")
            return (yield from self._call_user(f, args, kwargs, fr, e.line))
        b = self.builtins.get(name)
        if b is None:
            raise URScriptError(f"line {e.line}: unknown function {name}")
        try:
            if b.blocking:
                return (yield from b.fn(self, *args, **kwargs))
            return b.fn(self, *args, **kwargs)
        except TypeError as exc:
            raise URScriptError(f"line {e.line}: {name}(): {exc}") from None

    def _call_user(self, f: FuncDef, args: list[Any], kwargs: dict[str, Any], fr: _Frame,
                   line: int) -> Generator[Any, None, Any]:
        if len(args) > len(f.params):
            raise URScriptError(f"line {line}: {f.name}() takes {len(f.params)} arguments")
        loc: dict[str, Any] = {}
        for i, (p, default) in enumerate(f.params):
            if i < len(args):
                loc[p] = args[i]
            elif p in kwargs:
                loc[p] = kwargs.pop(p)
            elif default is not None:
                loc[p] = yield from self._eval(default, fr)
            else:
                raise URScriptError(f"line {line}: {f.name}() misses argument {p}")
        if kwargs:
            raise URScriptError(f"line {line}: {f.name}() has no parameter {sorted(kwargs)[0]}")
        try:
            yield from self._exec_block(f.body, _Frame(loc, frozenset(f.locals_declared)))
        except _Return as r:
            return r.value
        return None


def mark_purity(program: Program) -> None:
    """Mark every expression that runs statements or takes time (a call of a user function or
    of a blocking built-in, a ``run``) as impure; the others are evaluated without the
    scheduler's machinery."""

    def visit(e: Any) -> bool:
        if not isinstance(e, Node):
            return True
        pure = True
        for child in (e.a, e.b, e.c):
            if isinstance(child, Node):
                pure &= visit(child)
            elif isinstance(child, list):
                for item in child:
                    if isinstance(item, Node):
                        pure &= visit(item)
                    elif isinstance(item, tuple):
                        for x in item:
                            if isinstance(x, Node):
                                pure &= visit(x)
                            elif isinstance(x, list):
                                for y in x:
                                    pure &= visit(y)
            elif isinstance(child, dict):
                for item in child.values():
                    pure &= visit(item)
            elif isinstance(child, FuncDef):
                for _p, d in child.params:
                    visit(d)
                for st in child.body:
                    visit(st)
        if e.kind == "call":
            b = program.builtins.get(e.a)
            if e.a in program.funcs or b is None or b.blocking:
                pure = False
        if e.kind == "run":
            pure = False
        e.pure = pure
        return pure

    for s in program.top:
        visit(s)
