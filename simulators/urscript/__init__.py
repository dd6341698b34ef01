"""An executor of the URScript the station's UR program uses, written from UR's own documents,
so that the tests run ``robot-programs/ur/station_link.script`` unchanged, as a UR e-Series
controller runs it.

Sources (UR e-Series "Script Directory", SW 5.x; the text was read from a stored copy):
§9 Scoping rules; §10 Threads, §10.1 Threads and scope, §10.2 Thread scheduling; §14 Module motion
(§14.22 movej, §14.44 stopj); §15 Module internals (§15.3, §15.11, §15.13, §15.14, §15.48 sleep,
§15.56 sync); §16 Module urmath (§16.5, §16.9, §16.10, §16.11, §16.12, §16.28, §16.29); §17 Module
interfaces (§17.38 read_port_register, §17.70 write_port_register). UR support page "Modbus
Server" (16377): the server's function codes and exception codes.

Not found in the stored copy, so NOT confirmed: the directory's language chapters on numbers,
types, operators and flow of control. The examples of the pages read (§9, §10, §14.30, §15.26,
§15.49) show def/thread/end, local/global, run/kill, if/else, while, return, ``+ - * /``, ``<``,
list literals and list indexing; the executor also accepts ``elif``, ``and``, ``or``, ``not``,
``== != <= > >=`` and assignment to a list element, which no page read shows - a gap the
program header names.

Modules: :mod:`.lexer`, :mod:`.parser`, :mod:`.interp` (evaluator and 2 ms frame scheduler),
:mod:`.builtins`, :mod:`.arm`, :mod:`.modbus`, :mod:`.controller`.

``DEFAULT_BUDGET`` - statements one thread executes in one 2 ms frame before it is preempted
until the next frame. What UR publishes: the frame (§10.2: 500 Hz, "each thread is given a
'physical' (or robot) time slice of 0.002 seconds"; §14: the RuntimeMachine talks to the robot at
500 Hz) and that a thread which uses its slice up by computation waits for the next frame. UR
publishes no statement rate, so the budget is an assumption, and a low one is the pessimistic
one: the fewer statements fit into a frame, the longer every step takes and the more often a
thread is preempted in the middle of a computation. 25 is the smallest round value at which the
program's own requirement holds - its twelve ``act_joints`` writes (24 statements after a
``sync()``) land in one frame, so the station never reads half of a new value - and the tests
show the program meeting every deadline of the station at it; ``python -m
simulators.urscript.timing`` measures the frames each step takes at any budget (every deadline
is met down to 2 statements per frame). The issue's independent stand-in ran at 60.
"""

DEFAULT_BUDGET = 25

__all__ = ["DEFAULT_BUDGET"]
