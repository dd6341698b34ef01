"""Evaluator and task scheduler of the SPEL+ subset (see :mod:`simulators.epson`).

Each SPEL+ task runs on a Python thread, but only one at a time: the scheduler hands a baton to
one task, which runs until it has executed ``budget`` statements or waits (``Wait``, ``WaitNet``,
a motion), then hands it back. Time is the scheduler's simulated clock (``TICK_S`` a round), so
tests never depend on the wall clock. Semantics, each from its document:

* Types and their ranges [UG-TYPES]: storing a value outside a variable's type is an overflow
  error; a Double stored into an integer type must be integral (strict: the pages read do not
  say whether RC+ rounds or truncates); Boolean and numbers do not mix (strict).
* ``Global`` [REF-GLOBAL]: every Global is cleared when a function is started from the Run or
  Operator window, except those declared ``Preserve`` or ``Static`` (Epson's own library code
  declares ``Global NonStatic``, the default): :meth:`Runtime.run_from_window`.
* Tasks [REF-HALT], [REF-TASKINFO], [UG-BG]: normal tasks 1..32, background tasks 65..80; a task
  started by ``Xqt`` from a background task is a background task; a background task executes no
  manipulator command (an error); an emergency stop aborts the normal tasks, not the background
  ones. ``TaskInfo(task, 3)``: -1 not executing, 1 running, 2 waiting, 3 halted, 5 ended by an
  error (the states issue 43's checker read on [REF-TASKINFO]).
* Errors [UG-BG]: an error with no ``OnErr`` handler in the calling chain ends its task (state 5);
  in a background task it "cannot be recovered in AUTO mode": the task stays ended.
  ``OnErr GoTo label`` [EPSON-MODBUS]: the error continues at the label of the innermost function
  of the call chain that set a handler; ``Err`` is its number.
* ``SyncLock syncID [, timeOut]`` / ``SyncUnlock syncID`` [REF-SYNCLOCK]: syncID 0..63 for
  SyncLock, 1..63 for SyncUnlock (their pages differ; strict: ID 0 is never unlocked); a task
  waits while another holds the ID; with a time-out it goes on after it and ``Tw`` says whether
  it timed out; a second ``SyncLock`` of an ID the task holds is an error, as is unlocking an ID
  it does not hold; a task that ends (also by an error or an abort) releases its IDs (RC+ 6.0
  and later; RC+ 5.0 did not). [REF-SYNCLOCK] SPEL+ Language Reference (RC800), "SyncLock
  Statement" and "SyncUnlock Statement", SPEL_RC800/en/030/030-220/030-220-010/
  030-220-010-600.html and -610.html.
"""

from __future__ import annotations

import math
import re
import threading
from dataclasses import dataclass
from typing import Any, Callable

from simulators.epson.spel import TYPES, Function, Program

__all__ = ["SpelRuntimeError", "Runtime", "Task", "Point", "TICK_S", "DEFAULT_BUDGET"]

#: one scheduler round of simulated time
TICK_S = 0.001
#: statements a task executes per round before the next task runs (an assumption: Epson
#: publishes no statement rate; the tests meet the station's deadlines at it)
DEFAULT_BUDGET = 400

#: error numbers of the stand-in (Epson's own numbers are not reproduced: the program must not
#: depend on them; only ``Err <> 0`` is meaningful)
ERR_OVERFLOW, ERR_INDEX, ERR_TYPE, ERR_DIV0, ERR_NET, ERR_BG_MOTION, ERR_MOTOR_OFF, ERR_RANGE, \
    ERR_IK, ERR_ARG, ERR_ESTOP = range(9001, 9012)


class SpelRuntimeError(Exception):
    """A run-time error of a task (``number`` is what ``Err`` returns)."""

    def __init__(self, number: int, message: str, line: int = 0, axis: int = 0):
        self.number, self.line, self.axis = number, line, axis
        super().__init__(f"line {line}: error {number}: {message}")


class _Killed(BaseException):
    """The task was aborted (emergency stop, Quit): not an error a handler sees."""


class _Exit(Exception):
    def __init__(self, what: str):
        self.what = what


@dataclass
class Point:
    """A point: ``kind`` "joint" (deg, deg, mm, deg as JA gives them) or "xy" (x, y, z mm, u
    deg), ``hand`` "l" / "r" / None."""

    kind: str
    values: tuple[float, ...]
    hand: str | None = None


class Var:
    __slots__ = ("typ", "dims", "data", "quals")

    def __init__(self, typ: str, dims: tuple[int, ...], quals: set[str] | frozenset[str] = frozenset()):
        self.typ, self.dims, self.quals = typ, dims, set(quals)
        self.data: list[Any] = [self.zero()] * (math.prod(dims) if dims else 1)

    def zero(self) -> Any:
        return False if self.typ == "boolean" else 0.0 if self.typ in ("real", "double") else 0

    def clear(self) -> None:
        self.data = [self.zero()] * len(self.data)

    def index(self, idx: list[int], line: int) -> int:
        if len(idx) != len(self.dims):
            raise SpelRuntimeError(ERR_INDEX, f"{len(idx)} subscript(s) for {len(self.dims)} dimension(s)", line)
        flat = 0
        for i, n in zip(idx, self.dims):
            if not isinstance(i, int) or isinstance(i, bool):
                raise SpelRuntimeError(ERR_TYPE, f"subscript {i!r} is not an integer", line)
            if not 0 <= i < n:
                raise SpelRuntimeError(ERR_INDEX, f"subscript {i} outside 0..{n - 1}", line)
            flat = flat * n + i
        return flat


def convert(v: Any, typ: str, line: int) -> Any:
    """``v`` stored into a variable of type ``typ`` [UG-TYPES]."""
    if typ == "boolean":
        if not isinstance(v, bool):
            raise SpelRuntimeError(ERR_TYPE, f"{v!r} into a Boolean", line)
        return v
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise SpelRuntimeError(ERR_TYPE, f"{v!r} into a {typ}", line)
    if typ in ("real", "double"):
        return float(v)
    if isinstance(v, float):
        if not math.isfinite(v) or abs(v - round(v)) > 1e-9:
            raise SpelRuntimeError(ERR_TYPE, f"{v!r} is not integral: stored into a {typ} (strict)", line)
        v = int(round(v))
    lo, hi = TYPES[typ]  # type: ignore[misc]
    if not lo <= v <= hi:
        raise SpelRuntimeError(ERR_OVERFLOW, f"overflow: {v} does not fit a {typ} ({lo}..{hi})", line)
    return v


def _num(v: Any, line: int) -> Any:
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise SpelRuntimeError(ERR_TYPE, f"{v!r} is not a number", line)
    return v


_LONG = TYPES["long"]


def _int_result(v: Any, line: int) -> Any:
    if isinstance(v, int) and not _LONG[0] <= v <= _LONG[1]:  # type: ignore[index]
        raise SpelRuntimeError(ERR_OVERFLOW, f"overflow: intermediate {v} outside the 32-bit range", line)
    return v


class Task:
    def __init__(self, rt: "Runtime", number: int, fn: Function, background: bool):
        self.rt, self.number, self.fn, self.background = rt, number, fn, background
        self.resume = threading.Semaphore(0)
        self.state = 1
        self.wake = 0.0
        self.until: Callable[[], bool] | None = None
        self.budget = 0
        self.kill = False
        self.error: SpelRuntimeError | None = None
        self.last_err = 0
        self.thread = threading.Thread(target=self._run, name=f"spel-{number}-{fn.name}", daemon=True)

    def _run(self) -> None:
        self.resume.acquire()
        try:
            if self.kill:
                raise _Killed()
            Evaluator(self.rt, self).call(self.fn, [], 0)
            self.state = -1
        except _Killed:
            self.state = -1
        except SpelRuntimeError as exc:
            self.error = exc
            self.state = 5
            self.rt.errors.append((self.number, self.fn.name, exc))
        except BaseException as exc:  # noqa: BLE001 - an executor bug must show, not hang the scheduler
            self.error = SpelRuntimeError(0, f"executor failure: {exc!r}")
            self.state = 5
            self.rt.errors.append((self.number, self.fn.name, self.error))
        finally:
            self.rt.release_sync(self.number)
            self.rt.baton.release()

    def pause(self) -> None:
        """Hand the baton back; continue when the scheduler resumes this task."""
        self.rt.baton.release()
        self.resume.acquire()
        if self.kill:
            raise _Killed()

    def wait_time(self, seconds: float) -> None:
        self.wake = self.rt.now + seconds
        self.state = 2
        self.pause()
        self.state = 1

    def wait_until(self, cond: Callable[[], bool]) -> None:
        self.until = cond
        self.state = 2
        self.pause()
        self.state = 1


class Runtime:
    """The controller's program side: globals, points, memory bits, tasks and the clock."""

    def __init__(self, program: Program, devices: Any, budget: int = DEFAULT_BUDGET):
        self.program = program
        self.dev = devices
        self.budget = budget
        self.now = 0.0
        self.baton = threading.Semaphore(0)
        self.tasks: dict[int, Task] = {}
        self.errors: list[tuple[int, str, SpelRuntimeError]] = []
        self.globals = {name: Var(t, dims, q) for name, t, dims, q, _line in program.globals}
        self.points: dict[str, Point] = {}
        self.mem = [False] * 512
        #: SyncLock IDs held: syncID -> task number [REF-SYNCLOCK]
        self.sync: dict[int, int] = {}

    def release_sync(self, number: int) -> None:
        """A task that ends releases the sync IDs it holds (RC+ 6.0 and later) [REF-SYNCLOCK]."""
        for sync_id in [i for i, holder in self.sync.items() if holder == number]:
            del self.sync[sync_id]

    # ------------------------------------------------------------------ tasks
    def start(self, name: str, number: int | None = None, background: bool = False) -> Task:
        fn = self.program.functions[name.lower()]
        if number is None:
            span = range(65, 81) if background else range(1, 33)
            number = next((n for n in span if n not in self.tasks or self.tasks[n].state in (-1, 5)), None)
            if number is None:
                raise SpelRuntimeError(ERR_ARG, "no free task number")
        task = Task(self, number, fn, background)
        self.tasks[number] = task
        task.thread.start()
        return task

    def run_from_window(self, name: str = "main") -> Task:
        """Start ``name`` as the Run / Operator window does: the Globals not declared
        Preserve or Static are cleared first [REF-GLOBAL]."""
        for var in self.globals.values():
            if not var.quals & {"preserve", "static"}:
                var.clear()
        return self.start(name, 1)

    def abort_normal_tasks(self) -> None:
        """An emergency stop: every normal task ends [UG-BG]; background tasks go on."""
        for task in list(self.tasks.values()):
            if not task.background and task.state not in (-1, 5):
                task.kill = True
                task.resume.release()
                self.baton.acquire()
                task.thread.join(5.0)

    def task_state(self, number: int) -> int:
        task = self.tasks.get(number)
        return -1 if task is None else task.state

    def tick(self) -> None:
        """One round: each runnable task in task-number order, then the clock advances."""
        for number in sorted(self.tasks):
            task = self.tasks[number]
            if task.state in (-1, 5):
                continue
            if task.wake > self.now:
                continue
            if task.until is not None:
                if not task.until():
                    continue
                task.until = None
            task.budget = self.budget
            task.resume.release()
            self.baton.acquire()
        self.now += TICK_S

    def stop_all(self) -> None:
        for task in list(self.tasks.values()):
            if task.state not in (-1, 5):
                task.kill = True
                task.resume.release()
                self.baton.acquire()


_VALUE_FUNCS = {"int", "abs", "lshift", "rshift", "degtorad", "radtodeg", "chknet", "taskinfo", "agl",
                "pagl", "cx", "cy", "cz", "cu", "ja", "xy", "memsw"}
BUILTINS = frozenset(_VALUE_FUNCS | {"on", "off", "true", "false", "here", "tillon", "estopon", "err", "tw"})


class _Frame:
    __slots__ = ("fn", "vars", "handler")

    def __init__(self, fn: Function):
        self.fn = fn
        self.vars: dict[str, Var] = {}
        self.handler: str | None = None


class Evaluator:
    """Runs one task's statements."""

    def __init__(self, rt: Runtime, task: Task):
        self.rt, self.task = rt, task
        self.tillon = False
        self.tw = False

    # ------------------------------------------------------------------ functions
    def call(self, fn: Function, args: list[Any], line: int) -> Any:
        fr = _Frame(fn)
        for (pname, ptype), value in zip(fn.params, args):
            v = Var(ptype, ())
            v.data[0] = convert(value, ptype, line)
            fr.vars[pname] = v
        if fn.returns is not None:
            fr.vars[fn.name] = Var(fn.returns, ())
        for st in _decls(fn.body):
            for name, dims in st[2]:
                fr.vars[name] = Var(st[1], dims)
        body = fn.body
        i = 0
        while i < len(body):
            try:
                self.stmt(body[i], fr)
            except _Exit as ex:
                if ex.what != "function":
                    raise
                break
            except SpelRuntimeError as exc:
                if fr.handler is None:
                    raise
                self.task.last_err = exc.number
                self.rt.dev.last_error_axis = exc.axis
                i = fn.labels[fr.handler]
                fr.handler = None  # an error inside the handler is not caught by it (strict)
                continue
            i += 1
        return fr.vars[fn.name].data[0] if fn.returns is not None else None

    def block(self, body: list, fr: _Frame) -> None:
        for st in body:
            self.stmt(st, fr)

    # ------------------------------------------------------------------ statements
    def stmt(self, st: Any, fr: _Frame) -> None:
        task = self.task
        task.budget -= 1
        if task.budget <= 0:
            task.pause()
            task.budget = self.rt.budget
        kind = st[0]
        line = st[-1]
        if kind == "assign":
            self.assign(st[1], self.eval(st[2], fr), fr, line)
        elif kind == "callstmt":
            self.eval(st[1], fr, statement=True)
        elif kind == "if":
            for cond, body in st[1]:
                if self.cond(cond, fr, line):
                    self.block(body, fr)
                    return
            self.block(st[2], fr)
        elif kind == "for":
            self.for_(st, fr)
        elif kind == "do":
            try:
                while st[1] is None or self.cond(st[1], fr, line):
                    self.block(st[2], fr)
                    if st[1] is None:  # an empty spin still yields its statement
                        task.budget -= 1
            except _Exit as ex:
                if ex.what != "do":
                    raise
        elif kind == "exit":
            raise _Exit(st[1])
        elif kind == "decl":
            return
        elif kind == "wait":
            sec = _num(self.eval(st[1], fr), line)
            if sec < 0:
                raise SpelRuntimeError(ERR_ARG, "Wait with a negative time", line)
            task.wait_time(sec)
        elif kind == "xqt":
            self.rt.start(st[1], background=task.background)
        elif kind == "onerr":
            fr.handler = st[1]
        elif kind == "sync":
            self.sync(st, fr, line)
        else:
            self.rt.dev.statement(self, st, fr)

    def sync(self, st: Any, fr: _Frame, line: int) -> None:
        """``SyncLock`` / ``SyncUnlock`` [REF-SYNCLOCK]."""
        _k, op, id_expr, timeout_expr, _line = st
        sync_id = _num(self.eval(id_expr, fr), line)
        # SyncLock's page gives 0..63, SyncUnlock's 1..63: strict, an ID 0 cannot be unlocked
        lowest = 1 if op == "syncunlock" else 0
        if sync_id != int(sync_id) or not lowest <= sync_id <= 63:
            raise SpelRuntimeError(ERR_ARG, f"syncID {sync_id!r} outside {lowest}..63", line)
        sync_id = int(sync_id)
        held, me = self.rt.sync, self.task.number
        if op == "syncunlock":
            if held.get(sync_id) != me:
                raise SpelRuntimeError(ERR_ARG, f"SyncUnlock {sync_id}: this task did not lock it", line)
            del held[sync_id]
            return
        if held.get(sync_id) == me:
            raise SpelRuntimeError(ERR_ARG, f"SyncLock {sync_id} twice in a row", line)
        deadline = None
        if timeout_expr is not None:
            sec = _num(self.eval(timeout_expr, fr), line)
            if sec < 0:
                raise SpelRuntimeError(ERR_ARG, "SyncLock with a negative time-out", line)
            deadline = self.rt.now + sec
        if sync_id in held:
            self.task.wait_until(lambda: sync_id not in held or (deadline is not None and self.rt.now >= deadline))
        self.tw = sync_id in held
        if not self.tw:
            held[sync_id] = me

    def for_(self, st: Any, fr: _Frame) -> None:
        _k, var, start, end, step, body, line = st
        v = self.eval(start, fr)
        stop = self.eval(end, fr)
        inc = self.eval(step, fr)
        if inc == 0:
            raise SpelRuntimeError(ERR_ARG, "For with Step 0", line)
        self.assign(("name", var, line), v, fr, line)
        try:
            while True:
                cur = self.eval(("name", var, line), fr)
                if (inc > 0 and cur > stop) or (inc < 0 and cur < stop):
                    break
                self.block(body, fr)
                self.assign(("name", var, line), self.eval(("name", var, line), fr) + inc, fr, line)
        except _Exit as ex:
            if ex.what != "for":
                raise

    def cond(self, e: Any, fr: _Frame, line: int) -> bool:
        v = self.eval(e, fr)
        if not isinstance(v, bool):
            raise SpelRuntimeError(ERR_TYPE, f"a condition must be Boolean, got {v!r} (strict)", line)
        return v

    def var(self, name: str, fr: _Frame) -> Var | None:
        return fr.vars.get(name) or self.rt.globals.get(name)

    def assign(self, target: Any, value: Any, fr: _Frame, line: int) -> None:
        name = target[1]
        if re.fullmatch(r"p\d+", name):
            if not isinstance(value, Point):
                raise SpelRuntimeError(ERR_TYPE, f"{value!r} into point {name}", line)
            self.rt.points[name] = value
            return
        var = self.var(name, fr)
        if var is None:
            raise SpelRuntimeError(ERR_TYPE, f"{name} is not a variable", line)
        if target[0] == "call":
            idx = [self.eval(a, fr) for a in target[2]]
            var.data[var.index(idx, line)] = convert(value, var.typ, line)
        else:
            if var.dims:
                raise SpelRuntimeError(ERR_TYPE, f"{name} is an array", line)
            var.data[0] = convert(value, var.typ, line)

    # ------------------------------------------------------------------ expressions
    def eval(self, e: Any, fr: _Frame, statement: bool = False) -> Any:
        kind = e[0]
        if kind == "num":
            return e[1]
        if kind == "name":
            return self.name(e[1], fr, e[2])
        if kind == "paren":
            return self.eval(e[1], fr)
        if kind == "call":
            return self.call_expr(e, fr, statement)
        if kind == "bin":
            return self.binop(e[1], self.eval(e[2], fr), self.eval(e[3], fr), getattr(self, "_line", 0))
        if kind == "cmp":
            return self.compare(e[1], self.eval(e[2], fr), self.eval(e[3], fr))
        if kind == "neg":
            return _int_result(-_num(self.eval(e[1], fr), 0), 0)
        if kind == "not":
            v = self.eval(e[1], fr)
            if isinstance(v, bool):
                return not v
            return ~_num(v, 0) if isinstance(v, int) else _num(None, 0)
        if kind == "hand":
            p = self.eval(e[1], fr)
            return Point(p.kind, p.values, e[2])
        raise SpelRuntimeError(ERR_TYPE, f"expression {kind} not in the subset")

    def name(self, name: str, fr: _Frame, line: int) -> Any:
        var = self.var(name, fr)
        if var is not None:
            if var.dims:
                raise SpelRuntimeError(ERR_TYPE, f"{name} is an array", line)
            return var.data[0]
        if name in ("on", "true"):
            return True
        if name in ("off", "false"):
            return False
        if name == "tillon":
            return self.tillon
        if name == "tw":
            return self.tw
        if name == "err":
            return self.task.last_err
        if re.fullmatch(r"p\d+", name):
            if name not in self.rt.points:
                raise SpelRuntimeError(ERR_ARG, f"point {name} is not defined", line)
            return self.rt.points[name]
        fn = self.rt.program.functions.get(name)
        if fn is not None:
            return self.call(fn, [], line)
        return self.rt.dev.value(self, name, [], line)

    def call_expr(self, e: Any, fr: _Frame, statement: bool) -> Any:
        name, args, line = e[1], e[2], e[3]
        var = self.var(name, fr)
        if var is not None:
            return var.data[var.index([self.eval(a, fr) for a in args], line)]
        fn = self.rt.program.functions.get(name)
        values = [self.array_arg(a, fr) if a[0] == "array" else self.eval(a, fr) for a in args]
        if fn is not None:
            if not statement and fn.returns is None:
                raise SpelRuntimeError(ERR_TYPE, f"{name} returns no value", line)
            return self.call(fn, values, line)
        return self.rt.dev.value(self, name, values, line)

    def array_arg(self, a: Any, fr: _Frame) -> Var:
        var = self.var(a[1], fr)
        if var is None or not var.dims:
            raise SpelRuntimeError(ERR_TYPE, f"{a[1]} is not an array", a[2])
        return var

    @staticmethod
    def binop(op: str, a: Any, b: Any, line: int) -> Any:
        if op in ("and", "or", "xor"):
            if isinstance(a, bool) and isinstance(b, bool):
                return (a and b) if op == "and" else (a or b) if op == "or" else (a != b)
            if isinstance(a, int) and isinstance(b, int) and not isinstance(a, bool) and not isinstance(b, bool):
                return a & b if op == "and" else a | b if op == "or" else a ^ b
            raise SpelRuntimeError(ERR_TYPE, f"{op} of {a!r} and {b!r}: Boolean with Boolean or integer with integer (strict)", line)
        a, b = _num(a, line), _num(b, line)
        if op == "+":
            return _int_result(a + b, line)
        if op == "-":
            return _int_result(a - b, line)
        if op == "*":
            return _int_result(a * b, line)
        if op == "/":
            if b == 0:
                raise SpelRuntimeError(ERR_DIV0, "division by zero", line)
            return a / b
        if op == "mod":
            if not (isinstance(a, int) and isinstance(b, int)):
                raise SpelRuntimeError(ERR_TYPE, "Mod of a non-integer (strict)", line)
            if b == 0:
                raise SpelRuntimeError(ERR_DIV0, "Mod 0", line)
            return int(math.fmod(a, b))
        raise SpelRuntimeError(ERR_TYPE, f"operator {op}", line)

    @staticmethod
    def compare(op: str, a: Any, b: Any) -> bool:
        if isinstance(a, bool) or isinstance(b, bool):
            if not (isinstance(a, bool) and isinstance(b, bool)) or op not in ("=", "<>"):
                raise SpelRuntimeError(ERR_TYPE, f"{a!r} {op} {b!r}")
        else:
            _num(a, 0)
            _num(b, 0)
        return {"=": a == b, "<>": a != b, "<": a < b, ">": a > b, "<=": a <= b, ">=": a >= b}[op]


def _decls(body: list) -> Any:
    for st in body:
        if st[0] == "decl":
            yield st
        elif st[0] == "if":
            for _c, b in st[1]:
                yield from _decls(b)
            yield from _decls(st[2])
        elif st[0] == "for":
            yield from _decls(st[5])
        elif st[0] == "do":
            yield from _decls(st[2])
