"""A stand-in for an Epson RC700/RC90 SCARA controller running a SPEL+ project: the program
(:mod:`.interp`), the arm (the robot file's SCARA, :class:`simulators.arm_kinematics.
ArmKinematics`, never the station's kinematics), the TCP/IP ports and the motion statements.

Documents: SPEL+ Language Reference pages cited in StationLink.prg's header ([REF-JA], [REF-TILL],
[TCP-14.3]) and Epson's Modbus client [EPSON-MODBUS] (``ChkNet`` <= -3: port not open, -1 open
but not connected, else the bytes waiting; ``WaitNet #p, t`` sets ``TW`` on a timeout;
``ReadBin #p, buf(), n`` / ``WriteBin #p, buf(), n`` with ``UByte`` buffers). Where Epson is
silent, strict: ``ReadBin`` with fewer bytes waiting than asked is an error; writing to a
connection the client closed is an error; ``Go`` with the motors off, outside the robot's joint
range or from a background task is an error (the range error names its axis, which the
handler's ``ErrAxis`` returns).

:meth:`EpsonController.start` powers up as RC+ does with background tasks enabled: ``BgMain``
starts as task 65 [UG-BG], then ``main`` is started from the Run window (:meth:`restart_main`).
A pacing thread runs scheduler rounds to the wall clock (1 ms each) so that the station, a
separate process with wall-clock deadlines, sees the program at its real rate.
"""

from __future__ import annotations

import math
import socket
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np

from simulators.epson import interp as I
from simulators.epson.interp import Point, Runtime, SpelRuntimeError
from simulators.epson.spel import build

__all__ = ["EpsonController", "SHIPPED_PRG"]

SHIPPED_PRG = Path(__file__).resolve().parents[2] / "robot-programs" / "epson" / "StationLink.prg"
#: joint speeds at Speed 100 (rad/s, rad/s, mm/s, rad/s): a stand-in's, not Epson's data sheet
MAX_SPEED = np.array([6.0, 6.0, 1000.0, 20.0])


class NetPort:
    """One SPEL+ TCP/IP port configured as a server on ``host:port`` (the listening socket
    exists while the controller runs; OpenNet / CloseNet open and close the port's use)."""

    def __init__(self, host: str, port: int):
        self.listener = socket.create_server((host, port))
        self.listener.setblocking(False)
        self.host, self.port = host, self.listener.getsockname()[1]
        self.open = False
        self.conn: socket.socket | None = None
        self.buf = bytearray()
        self.peer_closed = False

    def accept(self) -> bool:
        try:
            conn, _ = self.listener.accept()
        except BlockingIOError:
            return False
        conn.setblocking(False)
        conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self.conn, self.buf, self.peer_closed = conn, bytearray(), False
        return True

    def pull(self) -> None:
        if self.conn is None or self.peer_closed:
            return
        while True:
            try:
                data = self.conn.recv(65536)
            except BlockingIOError:
                return
            except OSError:
                self.peer_closed = True
                return
            if not data:
                self.peer_closed = True
                return
            self.buf += data

    def chk(self) -> int:
        if not self.open:
            return -3
        if self.conn is None:
            return -1
        self.pull()
        if self.peer_closed and not self.buf:
            return -1
        return len(self.buf)

    def close(self) -> None:
        if self.conn is not None:
            self.conn.close()
        self.conn, self.open, self.buf = None, False, bytearray()


class Arm:
    """The SCARA's joints (rad, rad, mm, rad) and the one motion that changes them."""

    def __init__(self, q0, model_name: str = "sr800"):
        from simulators.arm_kinematics import ArmKinematics
        from station.io.robot.files import load_robot

        self.model = load_robot(model_name)
        self.kin = ArmKinematics([t.joint for t in self.model.transforms], self.model.nominal)
        self.range = np.asarray(self.model.joint_limits, dtype=float)
        self.q = np.array(q0, dtype=float)
        self.target: np.ndarray | None = None
        self.rate = np.zeros(4)
        self.moves = 0

    def go(self, q1: np.ndarray, pct: float) -> None:
        d = q1 - self.q
        t = float(np.max(np.abs(d) / (MAX_SPEED * pct / 100.0)))
        self.target = q1
        self.rate = d / t if t > 0 else np.zeros(4)
        self.moves += 1

    def stop(self) -> None:
        self.target = None

    def step(self, dt: float) -> None:
        if self.target is None:
            return
        nxt = self.q + self.rate * dt
        if np.all(np.abs(self.target - nxt) <= np.abs(self.rate) * dt + 1e-12) or not np.any(self.rate):
            self.q, self.target = self.target.copy(), None
        else:
            self.q = nxt

    def pose(self) -> tuple[float, float, float, float]:
        """x, y, z mm and u deg of the tool (the robot file's chain with its head K)."""
        T = self.kin.forward(self.q)
        return float(T[0, 3]), float(T[1, 3]), float(T[2, 3]), math.degrees(math.atan2(T[1, 0], T[0, 0]))

    def inverse(self, x: float, y: float, z: float, u_deg: float, hand: str) -> np.ndarray | None:
        from simulators.arm_kinematics import Unreachable

        c, s = math.cos(math.radians(u_deg)), math.sin(math.radians(u_deg))
        T = np.array([[c, -s, 0, x], [s, c, 0, y], [0, 0, 1, z], [0, 0, 0, 1.0]])
        try:
            # the stand-in's hands: /L with J2 > 0, /R with J2 < 0 (the program tests J2's sign)
            return self.kin.scara_inverse(T, elbow=1 if hand == "l" else -1)
        except (Unreachable, np.linalg.LinAlgError, ValueError):
            return None


class Devices:
    """What the program's statements reach outside the language: arm, ports, memory, motors."""

    def __init__(self, ctl: "EpsonController"):
        self.ctl = ctl
        self.last_error_axis = 0

    # ------------------------------------------------------------------ statements
    def statement(self, ev: Any, st: Any, fr: Any) -> None:
        kind, line = st[0], st[-1]
        if kind == "net":
            self.net(ev, st[1], ev.eval(st[2], fr), st[3], fr, line)
        elif kind == "robot":
            self.robot(ev, st[1], [a[1] if a[0] == "num" and isinstance(a[1], str) else ev.eval(a, fr) for a in st[2]], line)
        elif kind == "go":
            self.go(ev, ev.eval(st[1], fr), st[2], fr, line)
        else:
            raise SpelRuntimeError(I.ERR_TYPE, f"statement {kind} not in the subset", line)

    def _port(self, p: Any, line: int) -> NetPort:
        port = self.ctl.ports.get(p)
        if port is None:
            raise SpelRuntimeError(I.ERR_NET, f"TCP/IP port #{p} is not configured", line)
        return port

    def net(self, ev: Any, op: str, p: Any, args: list, fr: Any, line: int) -> None:
        port = self._port(p, line)
        task = ev.task
        if op == "opennet":
            if port.open:
                raise SpelRuntimeError(I.ERR_NET, f"port #{p} is already open", line)
            port.open = True
        elif op == "closenet":
            port.close()
        elif op == "waitnet":
            if not port.open:
                raise SpelRuntimeError(I.ERR_NET, f"WaitNet #{p}: the port is not open", line)
            limit = ev.eval(args[0], fr) if args else None
            deadline = None if limit is None else self.ctl.rt.now + float(limit)
            task.wait_until(lambda: port.conn is not None or port.accept() or
                            (deadline is not None and self.ctl.rt.now >= deadline))
            ev.tw = port.conn is None
        elif op in ("readbin", "writebin"):
            if len(args) != 2 or args[0][0] != "array":
                raise SpelRuntimeError(I.ERR_ARG, f"{op} #port, buf(), n is the subset's form", line)
            arr = ev.array_arg(args[0], fr)
            n = ev.eval(args[1], fr)
            if not isinstance(n, int) or not 0 <= n <= len(arr.data):
                raise SpelRuntimeError(I.ERR_ARG, f"{op}: {n} bytes for a buffer of {len(arr.data)}", line)
            if op == "readbin":
                if port.chk() < n:
                    raise SpelRuntimeError(I.ERR_NET, f"ReadBin #{p}: {n} bytes asked, {max(port.chk(), 0)} waiting (strict)", line)
                for i in range(n):
                    arr.data[i] = I.convert(port.buf[i], arr.typ, line)
                del port.buf[:n]
            else:
                out = []
                for v in arr.data[:n]:
                    if isinstance(v, bool) or not isinstance(v, int) or not 0 <= v <= 255:
                        raise SpelRuntimeError(I.ERR_ARG, f"WriteBin: {v!r} is not a byte 0..255", line)
                    out.append(v)
                if port.conn is None or port.peer_closed:
                    raise SpelRuntimeError(I.ERR_NET, f"WriteBin #{p}: not connected", line)
                try:
                    port.conn.sendall(bytes(out))
                except OSError as exc:
                    raise SpelRuntimeError(I.ERR_NET, f"WriteBin #{p}: {exc}", line) from None

    def robot(self, ev: Any, op: str, args: list, line: int) -> None:
        ctl = self.ctl
        if op in ("memon", "memoff"):
            ctl.rt.mem[int(args[0])] = op == "memon"
            return
        if ev.task.background and op in ("motor", "power", "speed", "accel", "tool"):
            raise SpelRuntimeError(I.ERR_BG_MOTION, f"{op}: a manipulator command in a background task [UG-BG]", line)
        if op == "motor":
            if args[0] == "on" and ctl.estop:
                raise SpelRuntimeError(I.ERR_ESTOP, "Motor On during an emergency stop", line)
            ctl.motor = args[0] == "on"
        elif op in ("speed", "accel"):
            for v in args:
                if isinstance(v, bool) or not isinstance(v, int) or not 1 <= v <= 100:
                    raise SpelRuntimeError(I.ERR_ARG, f"{op} {v!r}: a whole percent 1..100", line)
            if op == "speed":
                ctl.speed = args[0]
        elif op == "tool":
            if args[0] not in ctl.tools:
                raise SpelRuntimeError(I.ERR_ARG, f"Tool {args[0]} is not defined on this controller", line)
        elif op == "power":
            if args[0] not in ("high", "low"):
                raise SpelRuntimeError(I.ERR_ARG, "Power High / Low", line)

    def go(self, ev: Any, target: Any, till: Any, fr: Any, line: int) -> None:
        ctl = self.ctl
        if ev.task.background:
            raise SpelRuntimeError(I.ERR_BG_MOTION, "Go: a manipulator command in a background task [UG-BG]", line)
        if not ctl.motor:
            raise SpelRuntimeError(I.ERR_MOTOR_OFF, "Go with the motors off", line)
        q = self.joints_of(target, line)
        lo, hi = ctl.arm.range.T
        for j in range(4):
            if not lo[j] <= q[j] <= hi[j]:
                raise SpelRuntimeError(I.ERR_RANGE, f"joint {j + 1} outside the robot's range", line, axis=j + 1)
        ev.tillon = False
        ctl.arm.go(q, ctl.speed)
        while ctl.arm.target is not None:
            if till is not None and ev.cond(till, fr, line):
                ctl.arm.stop()
                ev.tillon = True
                return
            ev.task.wait_time(I.TICK_S)

    def joints_of(self, p: Any, line: int) -> np.ndarray:
        if not isinstance(p, Point):
            raise SpelRuntimeError(I.ERR_TYPE, f"{p!r} is not a point", line)
        if p.kind == "joint":
            v = np.array(p.values, dtype=float)
            return np.array([math.radians(v[0]), math.radians(v[1]), v[2], math.radians(v[3])])
        x, y, z, u = p.values
        q = self.ctl.arm.inverse(x, y, z, u, hand=p.hand or "r")
        if q is None:
            raise SpelRuntimeError(I.ERR_IK, "the point cannot be reached", line)
        return q

    # ------------------------------------------------------------------ functions
    def value(self, ev: Any, name: str, a: list, line: int) -> Any:
        ctl = self.ctl
        arm = ctl.arm
        if name == "int":
            return int(math.floor(I._num(a[0], line)))
        if name == "abs":
            return abs(I._num(a[0], line))
        if name in ("lshift", "rshift"):
            v, n = a
            if not all(isinstance(x, int) and not isinstance(x, bool) for x in a) or not 0 <= n <= 31:
                raise SpelRuntimeError(I.ERR_ARG, f"{name}({v!r}, {n!r})", line)
            return I._int_result(v << n if name == "lshift" else v >> n, line)
        if name == "degtorad":
            return math.radians(I._num(a[0], line))
        if name == "radtodeg":
            return math.degrees(I._num(a[0], line))
        if name == "chknet":
            return self._port(a[0], line).chk()
        if name == "taskinfo":
            if a[1] != 3:
                raise SpelRuntimeError(I.ERR_ARG, "TaskInfo(task, 3) only in the subset", line)
            return ctl.rt.task_state(a[0])
        if name == "memsw":
            return ctl.rt.mem[int(a[0])]
        if name == "estopon":
            return ctl.estop
        if name == "erraxis":
            return self.last_error_axis
        if name == "motor":
            return ctl.motor
        if name == "ja":
            return Point("joint", tuple(float(I._num(x, line)) for x in a))
        if name == "xy":
            return Point("xy", tuple(float(I._num(x, line)) for x in a))
        if name == "here":
            if ev.task.background:
                raise SpelRuntimeError(I.ERR_BG_MOTION, "Here in a background task [UG-BG]", line)
            return Point("xy", arm.pose())
        if name == "agl":
            if ev.task.background:
                raise SpelRuntimeError(I.ERR_BG_MOTION, "Agl in a background task [UG-BG]", line)
            j = a[0] - 1
            return float(arm.q[j]) if j == 2 else math.degrees(arm.q[j])
        if name == "pagl":
            q = self.joints_of(a[0], line)
            j = a[1] - 1
            return float(q[j]) if j == 2 else math.degrees(q[j])
        if name in ("cx", "cy", "cz", "cu"):
            p = a[0]
            if p.kind != "xy":
                raise SpelRuntimeError(I.ERR_TYPE, f"{name} of a joint point (not in the subset)", line)
            return p.values["xyzu".index(name[1])]
        raise SpelRuntimeError(I.ERR_TYPE, f"{name} is not a function of the subset", line)


BUILTINS = I.BUILTINS | {"erraxis", "motor"}


class EpsonController:
    """``EpsonController(source)``; ``ports={201: 0}`` maps SPEL+ TCP/IP ports to loopback TCP
    ports (0: any free one, see :attr:`address`)."""

    def __init__(self, source: str | None = None, q0=(0.0, 0.5, -50.0, 0.0), budget: int = I.DEFAULT_BUDGET,
                 host: str = "127.0.0.1", ports: dict[int, int] | None = None, motor: bool = False):
        self.source = SHIPPED_PRG.read_text(encoding="utf-8") if source is None else source
        self.program = build(self.source, BUILTINS)
        self.arm = Arm(q0)
        self.ports = {n: NetPort(host, p) for n, p in (ports or {201: 0}).items()}
        self.tools = {0, 1}
        self.speed = 5
        self.motor = motor
        self.estop = False
        self.lock = threading.RLock()
        self.rt = Runtime(self.program, Devices(self), budget)
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self.lag_resets = 0

    # ------------------------------------------------------------------ the line
    def power_up(self) -> None:
        """Project loaded with background tasks enabled: BgMain as task 65 [UG-BG]; then main
        from the Run window."""
        self.rt.start("BgMain", 65, background=True)
        self.restart_main()

    def restart_main(self) -> None:
        with self.lock:
            self.rt.run_from_window("main")

    def emergency_stop(self) -> None:
        with self.lock:
            self.estop = True
            self.motor = False
            self.arm.stop()
            self.rt.abort_normal_tasks()

    def reset_estop(self) -> None:
        with self.lock:
            self.estop = False

    def ticks(self, n: int) -> None:
        with self.lock:
            for _ in range(n):
                self.rt.tick()
                self.arm.step(I.TICK_S)

    def run_until(self, predicate, max_s: float) -> float:
        t0 = self.rt.now
        while not predicate():
            if self.rt.now - t0 > max_s:
                raise TimeoutError(f"not within {max_s} s of controller time")
            self.ticks(1)
        return self.rt.now - t0

    # ------------------------------------------------------------------ real time
    def start(self) -> "EpsonController":
        self.power_up()
        self._thread = threading.Thread(target=self._pace, name="spel-pace", daemon=True)
        self._thread.start()
        return self

    def _pace(self) -> None:
        t0 = time.monotonic()
        done = 0
        while not self._stop.is_set():
            due = int((time.monotonic() - t0) / I.TICK_S)
            if due - done > 500:
                self.lag_resets += 1
                done = due - 1
            if due > done:
                k = min(due - done, 20)
                self.ticks(k)
                done += k
            else:
                time.sleep(I.TICK_S / 2)

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(10.0)
        with self.lock:
            self.rt.stop_all()
        for p in self.ports.values():
            p.close()
            p.listener.close()

    def __enter__(self) -> "EpsonController":
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()

    @property
    def address(self) -> str:
        p = self.ports[201]
        return f"{p.host}:{p.port}"
