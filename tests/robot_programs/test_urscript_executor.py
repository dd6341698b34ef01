"""The URScript executor (simulators/urscript) keeps the rules of UR's Script Directory that the
station's program depends on, and stops a program the way a controller does on anything else."""

from __future__ import annotations

import re

import pytest

from simulators.urscript.arm import Arm
from simulators.urscript.builtins import PortRegisters, make_builtins
from simulators.urscript.interp import Program, mark_purity
from simulators.urscript.lexer import URScriptSyntaxError
from simulators.urscript.modbus import GENERAL_PURPOSE, UR_FUNCTION_CODES


def program(src: str, budget: int = 50) -> Program:
    arm = Arm()
    p = Program(src, make_builtins(arm, PortRegisters()), budget, on_frame=arm.step)
    mark_purity(p)
    return p


def run(src: str, frames: int = 5, budget: int = 50) -> Program:
    p = program(src, budget)
    for _ in range(frames):
        p.step_frame()
    if p.error is not None:
        raise p.error
    return p


def test_syntax_the_directory_does_not_show_is_refused():
    with pytest.raises(URScriptSyntaxError, match="modulo"):
        program("def f():\n  a = 5 % 2\nend\n")
    with pytest.raises(URScriptSyntaxError, match="next line"):
        program("def f():\n  a = [1,\n    2]\nend\n")
    with pytest.raises(URScriptSyntaxError, match="one statement per line"):
        program("def f():\n  a = 1 b = 2\nend\n")


def test_scoping_rules_of_section_9():
    p = run("""
def prog():
  a = 0
  global g = 1
  def f():
    a = 1
    local b = 2
    global c = b + 1
  end
  def h():
    local a = 5
    a = a + 1
    global d = a
  end
  f()
  h()
end
prog()
""")
    # first scope level: global; a free variable in f is that global; local shadows it in h
    assert p.globals["a"] == 1 and p.globals["c"] == 3 and p.globals["d"] == 6 and "b" not in p.globals


@pytest.mark.parametrize("body,match", [
    ("x = nosuch(1)", "unknown function nosuch"),
    ("x = y + 1", "undefined name y"),
    ("x = True + 1", r"\+ of a bool"),
    ("if 1:\n    x = 2\n  end", "condition must be a bool"),
    ("x = [1, 2] == 1", "comparing a list with a number"),
    ("x = [1, 2][2]", "index 2 outside"),
    ("x = 65536 * 65536", "32-bit"),
    ("x = 7 / 2", "int / int"),
    ("x = floor(True)", "expected a number"),
    ("write_port_register(130, 70000)", "outside"),
])
def test_a_runtime_exception_stops_the_program(body, match):
    p = program(f"def prog():\n  {body}\nend\nprog()\n")
    for _ in range(3):
        p.step_frame()
    assert p.error is not None and not p.running
    assert re.search(match, str(p.error)), str(p.error)


def test_threads_run_in_frames_and_are_preempted_at_the_budget():
    p = run("""
def prog():
  global n = 0
  global m = 0
  thread counter():
    while True:
      global n = n + 1
    end
  end
  thread ticker():
    while True:
      global m = m + 1
      sync()
    end
  end
  t1 = run counter()
  t2 = run ticker()
  sleep(1.0)
  kill t1
  kill t2
end
prog()
""", frames=520, budget=10)
    # the counter loop, two statements a pass, is preempted at 10 statements per frame; sync()
    # ends the ticker's frame; sleep(1.0) is 500 frames of physical time
    assert 2400 <= p.globals["n"] <= 2600
    assert 495 <= p.globals["m"] <= 501
    assert not p.running


def test_killing_a_finished_thread_stops_the_program():
    p = program("""
def prog():
  thread quick():
    x = 1
  end
  t = run quick()
  sleep(0.01)
  kill t
end
prog()
""")
    for _ in range(10):
        p.step_frame()
    assert p.error is not None and "no longer running" in str(p.error)


def test_port_registers_are_signed_in_the_script_and_words_on_modbus():
    ports = PortRegisters()
    ports.set_words(130, [0xFFFF, 0x8000, 0x7FFF])
    assert [ports.read_signed(a) for a in (130, 131, 132)] == [-1, -32768, 32767]  # §17.38
    ports.write_any(133, 65535)  # §17.70 accepts either range
    ports.write_any(134, -2)
    assert ports.words(133, 2) == [0xFFFF, 0xFFFE]
    assert ports.read_signed(133) == -1


def test_the_modbus_server_follows_the_ur_page():
    assert set(UR_FUNCTION_CODES) == {0x01, 0x02, 0x03, 0x04, 0x05, 0x06, 0x0F, 0x10}
    assert (GENERAL_PURPOSE.start, GENERAL_PURPOSE.stop) == (128, 256)


def test_movej_moves_the_arm_in_simulated_time():
    p = run("""
def prog():
  movej([1.0, 0, 0, 0, 0, 0], a=1.0, v=0.5)
  global done_at = 1
end
prog()
""", frames=1600)
    # a trapezoid of the leading axis: 1 rad at 0.5 rad/s, 1 rad/s²: 2.5 s
    assert p.globals["done_at"] == 1 and p.frames == 1600
