"""The built-in functions of the URScript subset, each as UR's e-Series Script Directory
(SW 5.x) describes it; the section is given beside each. Arguments of a wrong type stop the
program (:class:`~simulators.urscript.interp.URScriptError`).

The port registers (§17.38 / §17.70) are the controller's Modbus server registers
(:class:`PortRegisters`): the script reads a SIGNED value (-32768 : 32767) and may write either
range; the Modbus side (:mod:`simulators.urscript.modbus`) sees 16-bit words.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Generator
from typing import TYPE_CHECKING, Any

import numpy as np

from simulators.urscript.interp import Builtin, Pose, URScriptError, _is_num, check_int

if TYPE_CHECKING:
    from simulators.urscript.arm import Arm
    from simulators.urscript.interp import Program

__all__ = ["PortRegisters", "make_builtins"]


class PortRegisters:
    """The Modbus server's registers, addresses 0..65535, held as the script sees them (signed)."""

    def __init__(self) -> None:
        self._v: dict[int, int] = {}
        self.lock = threading.RLock()

    def read_signed(self, address: int) -> int:
        with self.lock:
            return self._v.get(address, 0)

    def write_any(self, address: int, value: int) -> None:
        """§17.70: "Value to be set in the port (0 : 65536) or (-32768 : 32767)"; stored as the
        signed 16-bit value of the same word (65536 itself does not fit a word and is refused)."""
        if not -32768 <= value <= 65535:
            raise URScriptError(f"write_port_register({address}, {value}): value outside (0 : 65535) and (-32768 : 32767)")
        with self.lock:
            self._v[address] = value - 65536 if value >= 32768 else value

    def words(self, address: int, count: int) -> list[int]:
        """Modbus: the 16-bit words (0..65535) of ``count`` registers."""
        with self.lock:
            return [self._v.get(a, 0) & 0xFFFF for a in range(address, address + count)]

    def set_words(self, address: int, words: list[int]) -> None:
        """Modbus: a client writes 16-bit words."""
        with self.lock:
            for i, w in enumerate(words):
                w = int(w) & 0xFFFF
                self._v[address + i] = w - 65536 if w >= 32768 else w


def _num(name: str, v: Any) -> float:
    if not _is_num(v):
        raise URScriptError(f"{name}: expected a number, got {type(v).__name__}")
    return float(v)


def _int(name: str, v: Any) -> int:
    if not isinstance(v, int) or isinstance(v, bool):
        raise URScriptError(f"{name}: expected an integer, got {type(v).__name__}")
    return v


def _joints(name: str, q: Any) -> np.ndarray:
    if isinstance(q, Pose) or not isinstance(q, list) or len(q) != 6 or not all(_is_num(x) for x in q):
        raise URScriptError(f"{name}: expected a list of six joint positions (a pose target is not supported here)")
    return np.array(q, dtype=float)


def _pose(name: str, x: Any) -> Pose:
    if not isinstance(x, Pose):
        raise URScriptError(f"{name}: expected a pose p[...]")
    return x


def _vec3(name: str, v: Any) -> np.ndarray:
    if not isinstance(v, (list, Pose)) or len(v) != 3 or not all(_is_num(x) for x in v):
        raise URScriptError(f"{name}: expected a list of three numbers")
    return np.array(v, dtype=float)


def make_builtins(arm: "Arm", ports: PortRegisters) -> dict[str, Builtin]:
    """The built-ins, bound to an arm and the port registers."""

    # ---------------------------------------------------------------- §14 Module motion
    def movej(prog: "Program", q, a=1.4, v=1.05, t=0, r=0) -> Generator[Any, None, None]:
        """§14.22 movej(q, a=1.4, v=1.05, t=0, r=0): "Move to position (linear in joint-space)";
        a, v of the leading axis. t and r are not supported (the program gives neither)."""
        if _num("movej t", t) != 0 or _num("movej r", r) != 0:
            raise URScriptError("movej: t and r are not supported by this executor")
        arm.movej(_joints("movej", q), _num("movej a", a), _num("movej v", v))
        yield ("until", lambda: arm.idle)

    def stopj(prog: "Program", a) -> Generator[Any, None, None]:
        """§14.44 stopj(a): "Decelerate joint speeds to zero"; a of the leading axis [rad/s^2]."""
        arm.stopj(_num("stopj a", a))
        yield ("until", lambda: arm.idle)

    # ---------------------------------------------------------------- §15 Module internals
    def get_actual_joint_positions(prog: "Program") -> list[float]:
        """§15.3: the joint positions read by the encoders, rad, a vector of length 6."""
        return [float(x) for x in arm.q]

    def get_forward_kin(prog: "Program", q=None, tcp=None) -> Pose:
        """§15.11 get_forward_kin(q='current_joint_positions', tcp='active_tcp')."""
        qq = arm.q if q is None else _joints("get_forward_kin", q)
        tt = Pose((0.0,) * 6) if tcp is None else _pose("get_forward_kin tcp", tcp)
        return Pose(arm.forward(qq, tt))

    def _ik(name: str, x, qnear, maxPositionError, maxOrientationError, tcp) -> np.ndarray | None:
        qq = arm.q if qnear is None else _joints(name + " qnear", qnear)
        tt = Pose((0.0,) * 6) if tcp is None else _pose(name + " tcp", tcp)
        return arm.inverse(_pose(name, x), qq, tt, _num(name, maxPositionError), _num(name, maxOrientationError))

    def get_inverse_kin(prog: "Program", x, qnear=None, maxPositionError=1e-10, maxOrientationError=1e-10,
                        tcp=None) -> list[float]:
        """§15.13 get_inverse_kin(x, qnear, maxPositionError=1e-10, maxOrientationError=1e-10,
        tcp='active_tcp'): the solution closest to qnear; a runtime exception when there is none
        (§15.14)."""
        q = _ik("get_inverse_kin", x, qnear, maxPositionError, maxOrientationError, tcp)
        if q is None:
            raise URScriptError("get_inverse_kin: no solution")
        return [float(v) for v in q]

    def get_inverse_kin_has_solution(prog: "Program", pose, qnear=None, maxPositionError=1e-10,
                                     maxOrientationError=1e-10, tcp=None) -> bool:
        """§15.14: True if get_inverse_kin has a solution."""
        return _ik("get_inverse_kin_has_solution", pose, qnear, maxPositionError, maxOrientationError, tcp) is not None

    def sleep(prog: "Program", t) -> Generator[Any, None, None]:
        """§15.48 sleep(t): sleep for t seconds; §10.2: it uses physical time."""
        yield ("sleep", prog.time + _num("sleep", t))

    def sync(prog: "Program") -> Generator[Any, None, None]:
        """§15.56 sync(): "Uses up the remaining 'physical' time a thread has in the current frame"."""
        yield ("sync",)

    # ---------------------------------------------------------------- §16 Module urmath
    def binary_list_to_integer(prog: "Program", l) -> int:  # noqa: E741 - the directory names it l
        """§16.5: the bools of l as a signed binary number, index 0 least significant; an empty
        list is 0; of more than 32 bools the first 32 count."""
        if not isinstance(l, list) or not all(isinstance(b, bool) for b in l):
            raise URScriptError("binary_list_to_integer: expected a list of bools")
        bits = l[:32]
        v = sum(1 << i for i, b in enumerate(bits) if b)
        if len(bits) == 32 and bits[31]:
            v -= 1 << 32
        return v

    def floor(prog: "Program", f) -> int:
        """§16.9 floor(f): "Returns largest integer not greater than f" (a rounded integer)."""
        return check_int(int(math.floor(_num("floor", f))), "floor")

    def make_list(prog: "Program", length, initial_value, capacity=None) -> list[Any]:
        """§16.10 make_list(length, initial_value, capacity=length)."""
        n = _int("make_list length", length)
        cap = n if capacity is None else _int("make_list capacity", capacity)
        if n < 0 or cap < n or isinstance(initial_value, list):
            raise URScriptError("make_list: bad length, capacity or initial value")
        return [initial_value] * n

    def get_list_length(prog: "Program", v) -> int:
        """§16.11 get_list_length(v): the number of entries of a list."""
        if not isinstance(v, list):
            raise URScriptError("get_list_length: expected a list")
        return len(v)

    def integer_to_binary_list(prog: "Program", x) -> list[bool]:
        """§16.12: "A list of 32 bools ... The bool at index 0 is the least significant bit" of
        the signed integer x."""
        v = _int("integer_to_binary_list", x) & 0xFFFFFFFF
        return [bool((v >> i) & 1) for i in range(32)]

    def rotvec2rpy(prog: "Program", rotation_vector) -> list[float]:
        """§16.28: RPY with Rrpy = Rz(yaw)Ry(pitch)Rx(roll) (extrinsic X-Y-Z)."""
        from scipy.spatial.transform import Rotation

        return [float(v) for v in Rotation.from_rotvec(_vec3("rotvec2rpy", rotation_vector)).as_euler("xyz")]

    def rpy2rotvec(prog: "Program", rpy_vector) -> list[float]:
        """§16.29: the rotation vector of Rz(yaw)Ry(pitch)Rx(roll)."""
        from scipy.spatial.transform import Rotation

        return [float(v) for v in Rotation.from_euler("xyz", _vec3("rpy2rotvec", rpy_vector)).as_rotvec()]

    # ---------------------------------------------------------------- §17 Module interfaces
    def read_port_register(prog: "Program", address) -> int:
        """§17.38: "The signed integer value held by the port (-32768 : 32767)"."""
        return ports.read_signed(_int("read_port_register", address))

    def write_port_register(prog: "Program", address, value) -> None:
        """§17.70: "Value to be set in the port (0 : 65536) or (-32768 : 32767)"."""
        ports.write_any(_int("write_port_register", address), _int("write_port_register", value))

    return {
        "movej": Builtin(movej, True, "§14.22"),
        "stopj": Builtin(stopj, True, "§14.44"),
        "get_actual_joint_positions": Builtin(get_actual_joint_positions, False, "§15.3"),
        "get_forward_kin": Builtin(get_forward_kin, False, "§15.11"),
        "get_inverse_kin": Builtin(get_inverse_kin, False, "§15.13"),
        "get_inverse_kin_has_solution": Builtin(get_inverse_kin_has_solution, False, "§15.14"),
        "sleep": Builtin(sleep, True, "§15.48"),
        "sync": Builtin(sync, True, "§15.56"),
        "binary_list_to_integer": Builtin(binary_list_to_integer, False, "§16.5"),
        "floor": Builtin(floor, False, "§16.9"),
        "make_list": Builtin(make_list, False, "§16.10"),
        "get_list_length": Builtin(get_list_length, False, "§16.11"),
        "integer_to_binary_list": Builtin(integer_to_binary_list, False, "§16.12"),
        "rotvec2rpy": Builtin(rotvec2rpy, False, "§16.28"),
        "rpy2rotvec": Builtin(rpy2rotvec, False, "§16.29"),
        "read_port_register": Builtin(read_port_register, False, "§17.38"),
        "write_port_register": Builtin(write_port_register, False, "§17.70"),
    }
