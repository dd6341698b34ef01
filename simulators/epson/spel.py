"""Lexer, preprocessor, parser and build checks of the SPEL+ subset StationLink.prg uses.

A program that breaks a rule below does not build: :func:`build` raises :class:`SpelBuildError`
listing every error with its line, as RC+ lists a build's errors. Each rule names its source;
where Epson's pages are silent the strictest reading is taken and marked "strict".

* Statements and their forms: SPEL+ Language Reference (statement pages cited in
  robot-programs/epson/StationLink.prg's header) and Epson's own SPEL+ code in the public RC+
  extension samples (Epson-Robots/rcplus-extensions, samples/rcplus-custom/
  VanguardModelPFScrewdriver/.../VGD_PF/Modbus.prg, "[EPSON-MODBUS]"): ``Function f (a As T) As T``
  ... ``Fend``, return by assigning the function's name, ``OnErr GoTo label`` with the label at
  the end, ``Exit Function``, ``Do While`` ... ``Loop``, ``For`` ... ``Next``, ``ReadBin #port,
  buf(), n``, ``WriteBin #port, buf(), n``, ``ChkNet(port)``, ``WaitNet #port, timeout``.
* A user function with arguments is called with parentheses, ``f(args)`` or ``Call f(args)``:
  every call in [EPSON-MODBUS] is written so; ``f a, b`` is a build error (strict).
* Names are not case-sensitive (SPEL+ keywords and names are written in any case in Epson's
  code, e.g. ``Index`` and ``index`` for one variable in [EPSON-MODBUS]): a local whose name
  equals a global's, a function's or a ``#define``'s in any case is a build error (strict: RC+
  may let it hide the global, which is worse).
* Keywords and point syntax are not identifiers (:data:`KEYWORDS`); ``P`` followed by a number
  or ``(`` is a point (SPEL+ point syntax ``P1``, ``P(n)``), so a variable ``p`` is refused.
* ``Mod`` written beside ``+``/``-`` without parentheses is refused (strict: no Epson page read
  gives the operators' precedence).
* One statement a line; ``'`` starts a comment; ``name:`` alone on a line is a label.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from typing import Any

__all__ = ["SpelBuildError", "Function", "Program", "build", "KEYWORDS", "TYPES"]

#: the data types of the RC+ User's Guide "Data types" [UG-TYPES] with their ranges; Real and
#: Double hold floats
TYPES: dict[str, tuple[int, int] | None] = {
    "boolean": None, "byte": (-128, 127), "ubyte": (0, 255), "short": (-32768, 32767),
    "ushort": (0, 65535), "integer": (-32768, 32767), "long": (-2 ** 31, 2 ** 31 - 1),
    "int32": (-2 ** 31, 2 ** 31 - 1), "uint32": (0, 2 ** 32 - 1), "real": None, "double": None,
}

#: SPEL+ keywords, statements and functions that cannot name a variable, a parameter, a function
#: or a #define (statements and functions of the Language Reference; Off / On, Speed, Err, Val and
#: Base are those issue 43 found used as names)
KEYWORDS = frozenset(w.lower() for w in """
 Abs Accel And As Agl Base ByRef Call ChkNet CloseNet CX CY CZ CU Date DegToRad Do Double Else
 ElseIf EndIf EResume Err ErrAxis EStopOn Exit False Fend For Function Global Go GoTo Here If In
 Int Integer JA Jump Local Long Loop LShift MemOff MemOn MemSw Mod Motor Move Next Not Off On OnErr
 OpenNet Or Out PAgl Power Preserve Print RadToDeg Range ReadBin Real Return RShift Send Server
 Speed Static NonStatic Step Stat String Sw TaskInfo Then Till TillOn Time To Tool True Val Wait
 WaitNet While WriteBin Xor XY Xqt Boolean Byte UByte Short UShort Int32 UInt32 Arm Point Error
 Halt Quit Resume Select Case Default Sin Cos Tan Sqr Atan Atan2 Str Hex Motor High Low TW
 SyncLock SyncUnlock
""".split())

_TOKEN = re.compile(r"""
 (?P<ws>[ \t]+)
|(?P<hex>&H[0-9A-Fa-f]+)
|(?P<num>(?:\d+\.\d*|\.\d+|\d+)(?:[eE][+-]?\d+)?)
|(?P<name>[A-Za-z_][A-Za-z0-9_]*\$?)
|(?P<op><>|<=|>=|[-+*/=<>(),#:])
""", re.X)


class SpelBuildError(Exception):
    """The program does not build; ``errors`` lists ``(line, message)``."""

    def __init__(self, errors: list[tuple[int, str]]):
        self.errors = errors
        super().__init__(f"{len(errors)} build error(s):\n" + "\n".join(f"  line {n}: {m}" for n, m in errors[:40]))


@dataclass
class Tok:
    kind: str
    text: str

    @property
    def low(self) -> str:
        return self.text.lower()


def _strip_comment(line: str) -> str:
    return line.split("'", 1)[0]  # the subset has no string literals


def _tokens(text: str, lineno: int, errors: list) -> list[Tok]:
    out: list[Tok] = []
    pos = 0
    while pos < len(text):
        m = _TOKEN.match(text, pos)
        if not m:
            errors.append((lineno, f"unexpected character {text[pos]!r}"))
            return []
        pos = m.end()
        kind = m.lastgroup or ""
        if kind == "ws":
            continue
        out.append(Tok(kind, m.group()))
    return out


# ---------------------------------------------------------------------------------- the AST
@dataclass
class Function:
    name: str
    params: list[tuple[str, str]]          # (lower name, type)
    returns: str | None                      # type or None
    body: list[Any]
    labels: dict[str, int] = field(default_factory=dict)  # top-level label -> statement index
    line: int = 0


@dataclass
class Program:
    globals: list[tuple[str, str, tuple[int, ...], set[str], int]]  # (name, type, dims, qualifiers, line)
    functions: dict[str, Function]
    defines: dict[str, Any]


class _Lines:
    def __init__(self, lines: list[tuple[int, list[Tok]]]):
        self.lines = lines
        self.i = 0

    def peek(self) -> tuple[int, list[Tok]] | None:
        return self.lines[self.i] if self.i < len(self.lines) else None

    def next(self) -> tuple[int, list[Tok]]:
        line = self.lines[self.i]
        self.i += 1
        return line


class _Parse(Exception):
    pass


class _Expr:
    """Recursive descent over one line's tokens. Precedence (strict where Epson is silent):
    Or/Xor < And < Not < comparison < + - < Mod < * / < unary - < primary."""

    def __init__(self, toks: list[Tok], lineno: int, parser: "_Parser"):
        self.t = toks
        self.k = 0
        self.line = lineno
        self.p = parser

    def peek(self, off: int = 0) -> Any:  # Tok or None
        return self.t[self.k + off] if self.k + off < len(self.t) else None

    def take(self, text: str | None = None) -> Tok:
        tok = self.peek()
        if tok is None or (text is not None and tok.low != text.lower()):
            raise _Parse(f"expected {text!r}, got {tok.text if tok else 'end of line'!r}")
        self.k += 1
        return tok

    def at(self, text: str) -> bool:
        tok = self.peek()
        return tok is not None and tok.low == text.lower()

    def done(self) -> bool:
        return self.k >= len(self.t)

    def expr(self) -> Any:
        left = self.and_()
        while self.at("or") or self.at("xor"):
            op = self.take().low
            left = ("bin", op, left, self.and_())
        return left

    def and_(self) -> Any:
        left = self.not_()
        while self.at("and"):
            self.take()
            left = ("bin", "and", left, self.not_())
        return left

    def not_(self) -> Any:
        if self.at("not"):
            self.take()
            return ("not", self.not_())
        return self.cmp()

    def cmp(self) -> Any:
        left = self.add()
        while self.peek() is not None and self.peek().text in ("=", "<>", "<", ">", "<=", ">="):
            op = self.take().text
            left = ("cmp", op, left, self.add())
        return left

    def add(self) -> Any:
        left = self.mod()
        while self.at("+") or self.at("-"):
            op = self.take().text
            right = self.mod()
            for side in (left, right):
                if side[0] == "bin" and side[1] == "mod":
                    raise _Parse("Mod beside + or - without parentheses: the precedence is not documented (strict)")
            left = ("bin", op, left, right)
        return left

    def mod(self) -> Any:
        left = self.mul()
        while self.at("mod"):
            self.take()
            left = ("bin", "mod", left, self.mul())
        return left

    def mul(self) -> Any:
        left = self.unary()
        while (self.at("*") or self.at("/")) and not self._hand_suffix():
            op = self.take().text
            left = ("bin", op, left, self.unary())
        return left

    def _hand_suffix(self) -> bool:
        nxt = self.peek(1)
        return self.at("/") and nxt is not None and nxt.low in ("l", "r") and self.peek(2) is None

    def unary(self) -> Any:
        if self.at("-"):
            self.take()
            return ("neg", self.unary())
        if self.at("+"):
            self.take()
            return self.unary()
        return self.primary()

    def primary(self) -> Any:
        tok = self.take()
        if tok.kind == "num":
            v = float(tok.text)
            return ("num", int(v) if re.fullmatch(r"\d+", tok.text) else v)
        if tok.kind == "hex":
            return ("num", int(tok.text[2:], 16))
        if tok.text == "(":
            e = self.expr()
            self.take(")")
            return ("paren", e)
        if tok.kind != "name":
            raise _Parse(f"unexpected {tok.text!r}")
        name = tok.low
        if name in self.p.defines:
            return ("num", self.p.defines[name])
        if self.at("("):
            self.take("(")
            args = []
            if not self.at(")"):
                args.append(self.arg())
                while self.at(","):
                    self.take(",")
                    args.append(self.arg())
            self.take(")")
            node: Any = ("call", name, args, self.line)
            if self._hand_suffix():  # XY(...) /L, /R: the point's hand
                self.take("/")
                node = ("hand", node, self.take().low)
            return node
        return ("name", name, self.line)

    def arg(self) -> Any:
        # an array argument is written buf() in Epson's code
        if self.peek() is not None and self.peek().kind == "name" and self.peek(1) is not None \
                and self.peek(1).text == "(" and self.peek(2) is not None and self.peek(2).text == ")":
            name = self.take().low
            self.take("(")
            self.take(")")
            return ("array", name, self.line)
        return self.expr()


_BLOCK_ENDS = {"fend", "next", "loop", "else", "elseif", "endif"}


class _Parser:
    def __init__(self, source: str):
        self.errors: list[tuple[int, str]] = []
        self.defines: dict[str, Any] = {}
        self.globals: list = []
        self.functions: dict[str, Function] = {}
        lines = []
        for n, raw in enumerate(source.splitlines(), 1):
            text = _strip_comment(raw).strip()
            if not text:
                continue
            if text.lower().startswith("#define"):
                self._define(text, n)
                continue
            if text.startswith("#"):
                self.errors.append((n, f"preprocessor directive not in the subset: {text.split()[0]}"))
                continue
            toks = _tokens(text, n, self.errors)
            if toks:
                lines.append((n, toks))
        self.src = _Lines(lines)

    def _define(self, text: str, n: int) -> None:
        parts = text.split(None, 2)
        if len(parts) != 3:
            self.errors.append((n, "#define needs a name and a value"))
            return
        name, value = parts[1], parts[2].strip()
        if name.lower() in KEYWORDS:
            self.errors.append((n, f"#define {name}: {name} is a SPEL+ keyword"))
        try:
            v: Any = int(value[2:], 16) if value.lower().startswith("&h") else (int(value) if re.fullmatch(r"-?\d+", value) else float(value))
        except ValueError:
            self.errors.append((n, f"#define {name}: only numbers are in the subset, got {value!r}"))
            return
        self.defines[name.lower()] = v

    # ------------------------------------------------------------------ top level
    def parse(self) -> Program:
        while self.src.peek() is not None:
            n, toks = self.src.next()
            head = toks[0].low
            try:
                if head == "global":
                    self._global(toks[1:], n)
                elif head == "function":
                    self._function(toks, n)
                else:
                    raise _Parse(f"{toks[0].text!r} outside a function")
            except _Parse as exc:
                self.errors.append((n, str(exc)))
        return Program(self.globals, self.functions, self.defines)

    def _decl_list(self, toks: list[Tok], n: int) -> tuple[str, list[tuple[str, tuple[int, ...]]]]:
        e = _Expr(toks, n, self)
        typ = e.take().low
        if typ not in TYPES:
            raise _Parse(f"unknown type {typ!r}")
        out = []
        while True:
            name = e.take()
            if name.kind != "name":
                raise _Parse(f"expected a name, got {name.text!r}")
            self._check_name(name.text, n)
            dims: tuple[int, ...] = ()
            if e.at("("):
                e.take("(")
                d = [e.expr()]
                while e.at(","):
                    e.take(",")
                    d.append(e.expr())
                e.take(")")
                dims = tuple(int(_const(x)) + 1 for x in d)
            out.append((name.low, dims))
            if e.done():
                break
            e.take(",")
        return typ, out

    def _check_name(self, name: str, n: int) -> None:
        low = name.lower()
        if low in KEYWORDS:
            self.errors.append((n, f"{name} is a SPEL+ keyword, not a name"))
        if re.fullmatch(r"p\d*", low):
            self.errors.append((n, f"{name} is point syntax (P, Pn), not a name"))

    def _global(self, toks: list[Tok], n: int) -> None:
        quals = set()
        while toks and toks[0].low in ("preserve", "static", "nonstatic"):
            quals.add(toks.pop(0).low)
        typ, names = self._decl_list(toks, n)
        for name, dims in names:
            self.globals.append((name, typ, dims, quals, n))

    def _function(self, toks: list[Tok], n: int) -> None:
        e = _Expr(toks, n, self)
        e.take("function")
        name = e.take()
        self._check_name(name.text, n)
        params: list[tuple[str, str]] = []
        if e.at("("):
            e.take("(")
            while not e.at(")"):
                pn = e.take()
                self._check_name(pn.text, n)
                e.take("as")
                pt = e.take().low
                if pt not in TYPES:
                    raise _Parse(f"parameter type {pt!r} not in the subset")
                params.append((pn.low, pt))
                if e.at(","):
                    e.take(",")
            e.take(")")
        returns = None
        if e.at("as"):
            e.take("as")
            returns = e.take().low
            if returns not in TYPES:
                raise _Parse(f"return type {returns!r} not in the subset")
        if not e.done():
            raise _Parse(f"unexpected {e.peek().text!r} after the function's header")
        fn = Function(name.low, params, returns, [], line=n)
        if fn.name in self.functions:
            self.errors.append((n, f"function {name.text} defined twice"))
        self.functions[fn.name] = fn
        fn.body = self._block(("fend",), fn)
        self.src.next()

    # ------------------------------------------------------------------ statements
    def _block(self, ends: tuple[str, ...], fn: Function, top: bool = True) -> list:
        body: list = []
        while True:
            line = self.src.peek()
            if line is None:
                raise _Parse(f"missing {'/'.join(ends)}")
            n, toks = line
            head = toks[0].low
            if head in ends or (head == "exit" and False):
                return body
            if head in _BLOCK_ENDS or head == "function":
                raise _Parse(f"{toks[0].text} where {'/'.join(ends)} was expected (line {n})")
            self.src.next()
            try:
                if len(toks) == 2 and toks[1].text == ":" and toks[0].kind == "name":
                    if not top:
                        raise _Parse("a label inside a block is not in the subset")
                    fn.labels[head] = len(body)
                    continue
                body.append(self._statement(toks, n, fn))
            except _Parse as exc:
                self.errors.append((n, str(exc)))

    def _statement(self, toks: list[Tok], n: int, fn: Function) -> Any:
        head = toks[0].low
        if head in TYPES:
            typ, names = self._decl_list(toks, n)
            return ("decl", typ, names, n)
        if head == "if":
            return self._if(toks, n, fn)
        if head == "for":
            e = _Expr(toks, n, self)
            e.take("for")
            var = e.take().low
            e.take("=")
            start = e.expr()
            e.take("to")
            end = e.expr()
            step: Any = ("num", 1)
            if e.at("step"):
                e.take("step")
                step = e.expr()
            body = self._block(("next",), fn, top=False)
            self.src.next()
            return ("for", var, start, end, step, body, n)
        if head == "do":
            cond = None
            if len(toks) > 1:
                e = _Expr(toks, n, self)
                e.take("do")
                e.take("while")
                cond = e.expr()
            body = self._block(("loop",), fn, top=False)
            _, end = self.src.next()
            if len(end) > 1:
                raise _Parse("Loop While / Until is not in the subset")
            return ("do", cond, body, n)
        if head == "exit":
            if len(toks) != 2 or toks[1].low not in ("function", "do", "for"):
                raise _Parse("Exit Function / Do / For")
            return ("exit", toks[1].low, n)
        if head == "call":
            e = _Expr(toks[1:], n, self)
            node = e.primary()
            if node[0] != "call" or not e.done():
                raise _Parse("Call f(args)")
            return ("callstmt", node, n)
        e = _Expr(toks, n, self)
        if head in _SIMPLE:
            return _SIMPLE[head](self, e, n)
        if toks[0].kind == "name" and head not in KEYWORDS:
            target = e.primary()
            if e.done():
                if target[0] == "call":
                    return ("callstmt", target, n)
                return ("callstmt", ("call", target[1], [], n), n)
            if e.at("="):
                e.take("=")
                value = e.expr()
                if not e.done():
                    raise _Parse(f"unexpected {e.peek().text!r}")
                return ("assign", target, value, n)
            raise _Parse(f"{toks[0].text} {toks[1].text} ...: a call with arguments needs parentheses, "
                         f"{toks[0].text}(...) or Call {toks[0].text}(...) (Epson's code always writes them)")
        raise _Parse(f"statement {toks[0].text!r} not in the subset")

    def _if(self, toks: list[Tok], n: int, fn: Function) -> Any:
        then = next((i for i, t in enumerate(toks) if t.low == "then"), None)
        if then is None:
            raise _Parse("If without Then")
        cond = _Expr(toks[1:then], n, self).expr()
        rest = toks[then + 1:]
        if rest:  # single-line If cond Then statement
            return ("if", [(cond, [self._statement(rest, n, fn)])], [], n)
        arms = [(cond, self._block(("elseif", "else", "endif"), fn, top=False))]
        other: list = []
        while True:
            m, end = self.src.next()
            if end[0].low == "elseif":
                then = next((i for i, t in enumerate(end) if t.low == "then"), None)
                if then is None or then != len(end) - 1:
                    raise _Parse("ElseIf cond Then")
                arms.append((_Expr(end[1:then], m, self).expr(), self._block(("elseif", "else", "endif"), fn, top=False)))
            elif end[0].low == "else":
                other = self._block(("endif",), fn, top=False)
            else:
                return ("if", arms, other, n)


def _port(e: _Expr) -> Any:
    e.take("#")
    return e.primary()


def _s_wait(p, e, n):
    e.take()
    return ("wait", e.expr(), n)


def _s_xqt(p, e, n):
    e.take()
    name = e.take().low
    if e.at("("):
        e.take("(")
        e.take(")")
    if not e.done():
        raise _Parse("Xqt funcName (no task number, no arguments in the subset)")
    return ("xqt", name, n)


def _s_sync(p, e, n):
    """``SyncLock syncID [, timeOut]`` and ``SyncUnlock syncID`` [REF-SYNCLOCK]."""
    op = e.take().low
    sync_id = e.expr()
    timeout = None
    if op == "synclock" and e.at(","):
        e.take(",")
        timeout = e.expr()
    if not e.done():
        raise _Parse(f"unexpected {e.peek().text!r}")
    return ("sync", op, sync_id, timeout, n)


def _s_onerr(p, e, n):
    e.take()
    e.take("goto")
    return ("onerr", e.take().low, n)


def _s_net(p, e, n):
    op = e.take().low
    port = _port(e)
    args = []
    if op == "opennet":
        e.take("as")
        e.take("server")
    while e.at(","):
        e.take(",")
        args.append(e.arg())
    if not e.done():
        raise _Parse(f"unexpected {e.peek().text!r}")
    return ("net", op, port, args, n)


def _s_onoff(p, e, n):
    op = e.take().low
    if op in ("memon", "memoff", "tool", "speed", "power"):
        args = [e.expr() if op != "power" else ("num", e.take().low)]
    else:  # Motor On / Off
        args = [("num", e.take().low)]
    while e.at(","):
        e.take(",")
        args.append(e.expr())
    return ("robot", op, args, n)


def _s_accel(p, e, n):
    e.take()
    a = e.expr()
    e.take(",")
    return ("robot", "accel", [a, e.expr()], n)


def _s_go(p, e, n):
    e.take()
    target = e.primary()
    till = None
    if e.at("till"):
        e.take("till")
        till = e.expr()
    if not e.done():
        raise _Parse(f"unexpected {e.peek().text!r}")
    return ("go", target, till, n)


_SIMPLE = {"wait": _s_wait, "xqt": _s_xqt, "onerr": _s_onerr, "opennet": _s_net, "waitnet": _s_net,
           "closenet": _s_net, "readbin": _s_net, "writebin": _s_net, "memon": _s_onoff,
           "memoff": _s_onoff, "tool": _s_onoff, "speed": _s_onoff, "motor": _s_onoff, "power": _s_onoff,
           "accel": _s_accel, "go": _s_go, "synclock": _s_sync, "syncunlock": _s_sync}


def _const(node: Any) -> Any:
    if node[0] == "num":
        return node[1]
    if node[0] == "neg":
        return -_const(node[1])
    if node[0] == "paren":
        return _const(node[1])
    if node[0] == "bin" and node[1] in "+-*":
        a, b = _const(node[2]), _const(node[3])
        return a + b if node[1] == "+" else a - b if node[1] == "-" else a * b
    raise _Parse("an array bound must be a constant")


def build(source: str, builtins: frozenset[str]) -> Program:
    """Parse and check ``source``; raise :class:`SpelBuildError` with every error found."""
    p = _Parser(source)
    prog = p.parse()
    errors = p.errors
    from simulators.epson.check import check_names

    errors += check_names(prog, builtins)
    if errors:
        raise SpelBuildError(sorted(errors))
    return prog
