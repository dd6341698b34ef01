"""The SPEL+ executor's own rules (simulators/epson/), each a program that breaks it: the first
version of StationLink.prg (commit e12d62d, kept as test data) does not build, with the errors
issue 43 found; values outside their type overflow; keywords and point syntax are no names; a
name hides no other in any case; a construct the subset does not know is an error."""

from __future__ import annotations

from pathlib import Path

import pytest

from simulators.epson.bench import Link
from simulators.epson.controller import BUILTINS, EpsonController
from simulators.epson.interp import ERR_OVERFLOW
from simulators.epson.spel import SpelBuildError, build

#: robot-programs/epson/StationLink.prg as issue 33 left it (git show e12d62d:...), unchanged
FIRST_VERSION = Path(__file__).parent / "data" / "StationLink_e12d62d.prg"


def build_errors(source: str) -> list[tuple[int, str]]:
    try:
        build(source, BUILTINS)
    except SpelBuildError as exc:
        return exc.errors
    return []


def test_the_first_version_does_not_build_and_every_error_is_listed():
    errors = build_errors(FIRST_VERSION.read_text(encoding="utf-8"))
    assert len(errors) == 126
    # calls of functions with arguments written without parentheses (Refuse seq, ...)
    unparenthesised = [n for n, m in errors if "a call with arguments needs parentheses" in m]
    assert len(unparenthesised) == 84
    assert (1416, "Mod beside + or - without parentheses: the precedence is not documented (strict)") in errors
    for line, message in [
        (169, "#define BASE: BASE is a SPEL+ keyword"),
        (746, "speed is a SPEL+ keyword, not a name"),
        (747, "err is a SPEL+ keyword, not a name"),
        (1048, "p is point syntax (P, Pn), not a name"),
        (670, "statement 'EResume' not in the subset"),
        (714, "Mod beside + or - without parentheses: the precedence is not documented (strict)"),
    ]:
        assert (line, message) in errors, (line, message)
    assert sum(m == "off is a SPEL+ keyword, not a name" for _n, m in errors) == 12
    assert (1311, "val is a SPEL+ keyword, not a name") in errors
    # StageTable's locals crcHi, crcLo would hide the globals CrcHi, CrcLo: compared with itself
    shadowed = sorted(m.split()[1] for n, m in errors if n == 915 and "has the name of a global" in m)
    assert shadowed == ["crchi", "crclo"]


def test_the_shipped_program_builds():
    from simulators.epson.controller import SHIPPED_PRG

    assert build_errors(SHIPPED_PRG.read_text(encoding="utf-8")) == []


@pytest.mark.parametrize("source, line, message", [
    ("Global Long Off\nFunction main\nFend", 1, "Off is a SPEL+ keyword, not a name"),
    ("Function main\n  Integer speed\nFend", 2, "speed is a SPEL+ keyword, not a name"),
    ("Function f(err As Long)\nFend\nFunction main\nFend", 1, "err is a SPEL+ keyword, not a name"),
    ("Function Val\nFend", 1, "Val is a SPEL+ keyword, not a name"),
    ("#define BASE 0\nFunction main\nFend", 1, "#define BASE: BASE is a SPEL+ keyword"),
    ("Function main\n  Long p(3)\nFend", 2, "p is point syntax (P, Pn), not a name"),
    ("Function main\n  Double P7\nFend", 2, "P7 is point syntax (P, Pn), not a name"),
])
def test_keywords_and_point_syntax_are_no_names(source, line, message):
    assert build_errors(source) == [(line, message)]


@pytest.mark.parametrize("source, line, what", [
    ("Global Long CrcHi\nFunction main\n  Long crcHi\nFend", 3, "local crchi of main has the name of a global"),
    ("Global Long crclo\nFunction main\n  Long CRCLO\nFend", 3, "local crclo of main has the name of a global"),
    ("Global Long Count\nFunction f(COUNT As Long)\nFend\nFunction main\nFend", 2,
     "local count of f has the name of a global"),
    ("Function helper\nFend\nFunction main\n  Long HELPER\nFend", 4, "local helper of main has the name of a function"),
    ("#define LIMIT 3\nFunction main\n  Integer limit\nFend", 3, "local limit of main has the name of a #define"),
    ("Function Foo\nFend\nFunction FOO\nFend", 3, "function FOO defined twice"),
])
def test_a_name_hides_no_other_in_any_case(source, line, what):
    errors = build_errors(source)
    assert len(errors) == 1 and errors[0][0] == line and errors[0][1].startswith(what), errors


@pytest.mark.parametrize("statement", ["EResume Next", "Select 1", "Halt main", "Print 1", "Jump P1"])
def test_a_construct_outside_the_subset_is_an_error_never_skipped(statement):
    errors = build_errors(f"Function main\n  {statement}\nFend")
    assert errors and errors[0][0] == 2, errors


def run_main(source: str, max_s: float = 1.0) -> EpsonController:
    ep = EpsonController(source)
    ep.rt.start("main", 1)
    ep.run_until(lambda: ep.rt.task_state(1) in (-1, 5), max_s)
    return ep


@pytest.mark.parametrize("typ, start, ok", [("Byte", 127, False), ("UByte", 254, True), ("UByte", 255, False),
                                             ("Integer", 32767, False), ("Long", 32767, True)])
def test_a_value_outside_its_type_overflows(typ, start, ok):
    ep = run_main(f"Function main\n  {typ} b\n  b = {start}\n  b = b + 1\nFend")
    try:
        if ok:
            assert ep.rt.task_state(1) == -1 and not ep.rt.errors
        else:
            assert ep.rt.task_state(1) == 5
            [(task, fn, exc)] = ep.rt.errors
            assert (task, fn, exc.number, exc.line) == (1, "main", ERR_OVERFLOW, 4), exc
    finally:
        ep.stop()


@pytest.mark.parametrize("typ", ["Byte", "UByte"])
def test_readbin_into_a_byte_buffer_overflows_on_a_byte_over_127(typ):
    """The first version's receive buffer was Byte (-128..127 [UG-TYPES]); Epson's Modbus client
    declares UByte: a Modbus frame's byte 0x80 overflows the first, not the second."""
    source = (f"Global {typ} Rx(9)\nFunction main\n  OpenNet #201 As Server\n  WaitNet #201\n"
              "  Do While ChkNet(201) < 2\n    Wait 0.01\n  Loop\n  ReadBin #201, Rx(), 2\nFend")
    ep = EpsonController(source)
    link = Link(ep)
    try:
        ep.rt.start("main", 1)
        ep.ticks(5)
        link.connect()
        link.send_raw(bytes([0x7F, 0x80]))
        ep.run_until(lambda: ep.rt.task_state(1) in (-1, 5), 1.0)
        if typ == "UByte":
            assert not ep.rt.errors and ep.rt.globals["rx"].data[:2] == [127, 128]
        else:
            [(_task, _fn, exc)] = ep.rt.errors
            assert exc.number == ERR_OVERFLOW and exc.line == 8 and "128" in str(exc)
    finally:
        link.close()
        ep.stop()


# SyncLock / SyncUnlock [REF-SYNCLOCK]: SPEL+ Language Reference (RC800), "SyncLock Statement",
# SPEL_RC800/en/030/030-220/030-220-010/030-220-010-600.html and "SyncUnlock Statement" (-610)
COUNTER = """Global Long Count, Done
Function main
  Xqt Adder
  Xqt Adder
Fend
Function Adder
  Integer i
  Long c
  For i = 1 To 20
    {lock}
    c = Count
    Wait 0.001
    Count = c + 1
    {unlock}
  Next
  Done = Done + 1
Fend
"""


@pytest.mark.parametrize("locked", [True, False])
def test_synclock_keeps_a_read_modify_write_whole_across_tasks(locked):
    """Two tasks add 20 each to one Global, reading it, waiting, writing it back: with the lock
    the sum is 40; without it (the check can fail) updates are lost."""
    source = COUNTER.format(lock="SyncLock 1" if locked else "", unlock="SyncUnlock 1" if locked else "")
    ep = EpsonController(source)
    try:
        ep.rt.start("main", 1)
        ep.run_until(lambda: ep.rt.globals["done"].data[0] == 2, 2.0)
        assert not ep.rt.errors
        count = ep.rt.globals["count"].data[0]
        assert count == 40 if locked else count < 40
        assert ep.rt.sync == {}
    finally:
        ep.stop()


@pytest.mark.parametrize("body, message", [
    ("SyncLock 3\n  SyncLock 3", "SyncLock 3 twice in a row"),
    ("SyncUnlock 3", "SyncUnlock 3: this task did not lock it"),
    ("SyncLock 64", "syncID 64 outside 0..63"),
    ("SyncLock 0\n  SyncUnlock 0", "syncID 0 outside 1..63"),  # the two pages differ: strict
])
def test_synclock_misuse_is_an_error(body, message):
    ep = run_main(f"Function main\n  {body}\nFend")
    try:
        [(_task, _fn, exc)] = ep.rt.errors
        assert message in str(exc)
        assert ep.rt.sync == {}  # the task that ended released what it held
    finally:
        ep.stop()


def test_synclock_waits_for_the_holder_and_a_timeout_sets_tw():
    """A task that ends releases its IDs (RC+ 6.0 and later); SyncLock with a time-out goes on
    after it with Tw = True, and takes the ID with Tw = False once it is free."""
    source = """Global Boolean First, Second
Function main
  Xqt Holder
  Wait 0.01
  SyncLock 5, 0.05
  First = Tw
  SyncLock 5, 1
  Second = Tw
  SyncUnlock 5
Fend
Function Holder
  SyncLock 5
  Wait 0.2
Fend
"""
    ep = EpsonController(source)
    try:
        ep.rt.start("main", 1)
        ep.run_until(lambda: ep.rt.task_state(1) in (-1, 5), 2.0)
        assert not ep.rt.errors
        assert ep.rt.globals["first"].data[0] is True and ep.rt.globals["second"].data[0] is False
        assert ep.rt.now == pytest.approx(0.2, abs=0.005)  # main took the ID when Holder ended
    finally:
        ep.stop()
