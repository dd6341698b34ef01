"""Tokenizer of the URScript subset the station's program uses.

What it accepts, and what it refuses, follows the pages of UR's e-Series Script Directory
(SW 5.x) that were found and read (``simulators/urscript/__init__.py`` lists them):

* one statement per line; a line ends a statement. A newline inside brackets (an expression
  continued onto a second line) is refused: no page of the directory shows it.
* ``#`` starts a comment to the end of the line.
* numbers (``12``, ``0.5``, ``1e-6``), strings in double quotes, names, the keywords and the
  operators ``+ - * / == != < <= > >= = ( ) [ ] , :`` and the pose prefix ``p[``.
* ``%`` is refused: the directory describes no modulo operator (it appears once, inside an
  example of §15.49 ``time()``, but is never described), so a program must not rely on it.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

__all__ = ["Token", "tokenize", "URScriptSyntaxError", "KEYWORDS"]

KEYWORDS = frozenset({
    "def", "thread", "end", "if", "elif", "else", "while", "return", "global", "local", "run", "kill",
    "join", "and", "or", "not", "True", "False", "break", "continue",
})

_TOKEN = re.compile(r"""
    (?P<ws>[ \t]+)
  | (?P<comment>\#[^\n]*)
  | (?P<nl>\r?\n)
  | (?P<num>(?:\d+\.\d*|\.\d+|\d+)(?:[eE][+-]?\d+)?)
  | (?P<str>"[^"\n]*")
  | (?P<pose>p\[)
  | (?P<name>[A-Za-z_][A-Za-z_0-9]*)
  | (?P<op>==|!=|<=|>=|[-+*/<>=()\[\],:.])
  | (?P<bad>.)
""", re.VERBOSE)


class URScriptSyntaxError(Exception):
    """The program does not parse (the controller refuses to start it)."""


@dataclass(frozen=True)
class Token:
    kind: str  # "num", "str", "name", "kw", "op", "nl", "eof"
    text: str
    line: int


def tokenize(source: str) -> list[Token]:
    """The tokens of ``source``; a newline token ends every non-empty line."""
    out: list[Token] = []
    line = 1
    depth = 0
    for m in _TOKEN.finditer(source):
        kind = m.lastgroup
        text = m.group()
        if kind in ("ws", "comment"):
            continue
        if kind == "nl":
            if depth:
                raise URScriptSyntaxError(f"line {line}: an expression continues onto the next line inside brackets; "
                                          f"the Script Directory shows one statement per line")
            if out and out[-1].kind != "nl":
                out.append(Token("nl", "\n", line))
            line += 1
            continue
        if kind == "bad":
            what = "the modulo operator '%' is not described in the Script Directory" if text == "%" \
                else f"unexpected character {text!r}"
            raise URScriptSyntaxError(f"line {line}: {what}")
        if kind == "name" and text in KEYWORDS:
            kind = "kw"
        if kind == "pose":
            depth += 1
        elif kind == "op" and text in "([":
            depth += 1
        elif kind == "op" and text in ")]":
            depth -= 1
            if depth < 0:
                raise URScriptSyntaxError(f"line {line}: unbalanced {text!r}")
        out.append(Token(kind or "bad", text, line))
    if depth:
        raise URScriptSyntaxError(f"line {line}: unclosed bracket at the end of the program")
    if out and out[-1].kind != "nl":
        out.append(Token("nl", "\n", line))
    out.append(Token("eof", "", line))
    return out
