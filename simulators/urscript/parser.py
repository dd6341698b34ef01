"""Parser of the URScript subset (tokens from :mod:`simulators.urscript.lexer`) into a small AST.

Grammar (one statement per line; blocks close with ``end``)::

    program   := { stmt }
    stmt      := funcdef | if | while | "return" [expr] | ["global" | "local"] target "=" expr
               | "kill" expr | "join" expr | "break" | "continue" | expr
    funcdef   := ("def" | "thread") NAME "(" [param {"," param}] ")" ":" { stmt } "end"
    if        := "if" expr ":" { stmt } { "elif" expr ":" { stmt } } [ "else" ":" { stmt } ] "end"
    while     := "while" expr ":" { stmt } "end"
    expr      := or-expression of and / not / comparisons / + - / * / / unary - / call, index
    atom      := NUMBER | STRING | True | False | NAME | "[" list "]" | "p[" list "]" | "(" expr ")"
               | "run" NAME "(" ")"

Scope and thread rules are the Script Directory's §9 and §10 (see the evaluator).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from simulators.urscript.lexer import Token, URScriptSyntaxError, tokenize

__all__ = ["parse", "Node", "FuncDef"]


@dataclass(eq=False)
class Node:
    kind: str
    line: int
    a: Any = None
    b: Any = None
    c: Any = None
    pure: bool = True  # an expression without a call that can take time or run statements


@dataclass(eq=False)
class FuncDef:
    name: str
    params: list[tuple[str, Node | None]]
    body: list[Node]
    is_thread: bool
    line: int
    locals_declared: set[str] = field(default_factory=set)
    assigned: set[str] = field(default_factory=set)
    globals_declared: set[str] = field(default_factory=set)


_COMPARE = ("==", "!=", "<", "<=", ">", ">=")


class _Parser:
    def __init__(self, tokens: list[Token]):
        self.t = tokens
        self.i = 0

    # ------------------------------------------------------------------ helpers
    @property
    def tok(self) -> Token:
        return self.t[self.i]

    def error(self, msg: str) -> URScriptSyntaxError:
        return URScriptSyntaxError(f"line {self.tok.line}: {msg} (at {self.tok.text!r})")

    def accept(self, text: str) -> bool:
        if self.tok.text == text and self.tok.kind in ("op", "kw", "pose"):
            self.i += 1
            return True
        return False

    def expect(self, text: str) -> Token:
        if not self.accept(text):
            raise self.error(f"expected {text!r}")
        return self.t[self.i - 1]

    def name(self) -> str:
        if self.tok.kind != "name":
            raise self.error("expected a name")
        self.i += 1
        return self.t[self.i - 1].text

    def end_of_line(self) -> None:
        if self.tok.kind != "nl":
            raise self.error("expected the end of the line (one statement per line)")
        self.i += 1

    # ------------------------------------------------------------------ statements
    def block(self, stop: tuple[str, ...]) -> list[Node]:
        out = []
        while not (self.tok.kind == "kw" and self.tok.text in stop):
            if self.tok.kind == "eof":
                raise self.error(f"missing {' or '.join(stop)!r}")
            out.append(self.statement())
        return out

    def statement(self) -> Node:
        tok = self.tok
        line = tok.line
        if tok.kind == "kw":
            if tok.text in ("def", "thread"):
                self.i += 1
                return self.funcdef(tok.text == "thread", line)
            if tok.text == "if":
                return self.if_stmt()
            if tok.text == "while":
                self.i += 1
                cond = self.expr()
                self.expect(":")
                self.end_of_line()
                body = self.block(("end",))
                self.expect("end")
                self.end_of_line()
                return Node("while", line, cond, body)
            if tok.text == "return":
                self.i += 1
                value = None if self.tok.kind == "nl" else self.expr()
                self.end_of_line()
                return Node("return", line, value)
            if tok.text in ("kill", "join"):
                self.i += 1
                target = self.expr()
                self.end_of_line()
                return Node(tok.text, line, target)
            if tok.text in ("break", "continue"):
                self.i += 1
                self.end_of_line()
                return Node(tok.text, line)
            if tok.text in ("global", "local"):
                self.i += 1
                target = Node("name", line, self.name())
                self.expect("=")
                value = self.expr()
                self.end_of_line()
                return Node("assign", line, target, value, tok.text)
        expr = self.expr()
        if self.accept("="):
            if expr.kind not in ("name", "index", "attr"):
                raise self.error("cannot assign to this expression")
            if expr.kind == "attr":
                raise self.error("assignment to a struct member is not used by this subset")
            value = self.expr()
            self.end_of_line()
            return Node("assign", line, expr, value, None)
        self.end_of_line()
        return Node("expr", line, expr)

    def funcdef(self, is_thread: bool, line: int) -> Node:
        name = self.name()
        self.expect("(")
        params: list[tuple[str, Node | None]] = []
        if not self.accept(")"):
            while True:
                p = self.name()
                default = self.expr() if self.accept("=") else None
                params.append((p, default))
                if self.accept(")"):
                    break
                self.expect(",")
        if is_thread and params:
            raise self.error("a thread cannot take parameters (§10)")
        self.expect(":")
        self.end_of_line()
        body = self.block(("end",))
        self.expect("end")
        self.end_of_line()
        return Node("def", line, FuncDef(name, params, body, is_thread, line))

    def if_stmt(self) -> Node:
        line = self.tok.line
        branches = []
        self.expect("if")
        while True:
            cond = self.expr()
            self.expect(":")
            self.end_of_line()
            body = self.block(("elif", "else", "end"))
            branches.append((cond, body))
            if not self.accept("elif"):
                break
        orelse: list[Node] = []
        if self.accept("else"):
            self.expect(":")
            self.end_of_line()
            orelse = self.block(("end",))
        self.expect("end")
        self.end_of_line()
        return Node("if", line, branches, orelse)

    # ------------------------------------------------------------------ expressions
    def expr(self) -> Node:
        left = self.and_expr()
        while self.tok.text == "or" and self.tok.kind == "kw":
            line = self.tok.line
            self.i += 1
            left = Node("bool", line, "or", left, self.and_expr())
        return left

    def and_expr(self) -> Node:
        left = self.not_expr()
        while self.tok.text == "and" and self.tok.kind == "kw":
            line = self.tok.line
            self.i += 1
            left = Node("bool", line, "and", left, self.not_expr())
        return left

    def not_expr(self) -> Node:
        if self.tok.text == "not" and self.tok.kind == "kw":
            line = self.tok.line
            self.i += 1
            return Node("unary", line, "not", self.not_expr())
        return self.comparison()

    def comparison(self) -> Node:
        left = self.additive()
        if self.tok.kind == "op" and self.tok.text in _COMPARE:
            op = self.tok.text
            line = self.tok.line
            self.i += 1
            left = Node("bin", line, op, left, self.additive())
            if self.tok.kind == "op" and self.tok.text in _COMPARE:
                raise self.error("chained comparisons are not used by this subset")
        return left

    def additive(self) -> Node:
        left = self.term()
        while self.tok.kind == "op" and self.tok.text in ("+", "-"):
            op = self.tok.text
            line = self.tok.line
            self.i += 1
            left = Node("bin", line, op, left, self.term())
        return left

    def term(self) -> Node:
        left = self.unary()
        while self.tok.kind == "op" and self.tok.text in ("*", "/"):
            op = self.tok.text
            line = self.tok.line
            self.i += 1
            left = Node("bin", line, op, left, self.unary())
        return left

    def unary(self) -> Node:
        if self.tok.kind == "op" and self.tok.text == "-":
            line = self.tok.line
            self.i += 1
            return Node("unary", line, "-", self.unary())
        return self.postfix()

    def postfix(self) -> Node:
        node = self.atom()
        while True:
            if self.tok.kind == "op" and self.tok.text == "(":
                if node.kind != "name":
                    raise self.error("only a named function can be called")
                self.i += 1
                args, kwargs = self.arguments()
                node = Node("call", node.line, node.a, args, kwargs)
            elif self.tok.kind == "op" and self.tok.text == "[":
                self.i += 1
                index = self.expr()
                self.expect("]")
                node = Node("index", node.line, node, index)
            elif self.tok.kind == "op" and self.tok.text == ".":
                self.i += 1
                node = Node("attr", node.line, node, self.name())
            else:
                return node

    def arguments(self) -> tuple[list[Node], dict[str, Node]]:
        args: list[Node] = []
        kwargs: dict[str, Node] = {}
        if self.accept(")"):
            return args, kwargs
        while True:
            if self.tok.kind == "name" and self.t[self.i + 1].text == "=" and self.t[self.i + 1].kind == "op":
                key = self.name()
                self.i += 1
                kwargs[key] = self.expr()
            else:
                if kwargs:
                    raise self.error("a positional argument after a keyword argument")
                args.append(self.expr())
            if self.accept(")"):
                return args, kwargs
            self.expect(",")

    def items(self, close: str) -> list[Node]:
        out: list[Node] = []
        if self.accept(close):
            return out
        while True:
            out.append(self.expr())
            if self.accept(close):
                return out
            self.expect(",")

    def atom(self) -> Node:
        tok = self.tok
        line = tok.line
        if tok.kind == "num":
            self.i += 1
            text = tok.text
            value: Any = float(text) if any(c in text for c in ".eE") else int(text)
            return Node("const", line, value)
        if tok.kind == "str":
            self.i += 1
            return Node("const", line, tok.text[1:-1])
        if tok.kind == "kw" and tok.text in ("True", "False"):
            self.i += 1
            return Node("const", line, tok.text == "True")
        if tok.kind == "kw" and tok.text == "run":
            self.i += 1
            name = self.name()
            self.expect("(")
            self.expect(")")
            return Node("run", line, name, pure=False)
        if tok.kind == "name":
            self.i += 1
            return Node("name", line, tok.text)
        if tok.kind == "pose":
            self.i += 1
            return Node("pose", line, self.items("]"))
        if tok.kind == "op" and tok.text == "[":
            self.i += 1
            return Node("list", line, self.items("]"))
        if tok.kind == "op" and tok.text == "(":
            self.i += 1
            inner = self.expr()
            self.expect(")")
            return inner
        raise self.error("expected an expression")


def parse(source: str) -> list[Node]:
    """The program's top-level statements."""
    p = _Parser(tokenize(source))
    out = []
    while p.tok.kind != "eof":
        out.append(p.statement())
    return out
