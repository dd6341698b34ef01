"""Simulated probe-head unit: physics (true geometry + noise) and a serial server.

* :class:`ProbeHeadPhysics` turns the true cube pose into readings: the simulator's own contact
  physics (:mod:`simulators.probe_contact`, not the station's solver), Gaussian noise per probe
  (default σ 0.5 µm), quantised to the protocol's 0.1 µm, markers where a probe misses or leaves
  its stroke.
* :class:`ProbeHeadServer` speaks one dialect of :mod:`drivers.probe_dialects` on a
  pseudo-terminal (``protocol``: station-ascii, the default; keyence-dl-rs1a; mitutoyo-ga, the
  units of :mod:`simulators.probe_dialect_units`); ``.port`` is the slave device path for
  ``serial.serial_for_url``. Replies are paced at the unit's baud rate (start + data + parity +
  stop bits per byte) so throughput is realistic. The unit has its own line settings
  (``baudrate``, ``bytesize``, ``parity``; None: the dialect's factory default); where the pty
  exposes the station's settings (termios of the slave: the baud rate on Linux, whose ptys force
  CS8 and clear PARENB; the data bits and parity where they are kept) a station whose settings
  differ gets garbled replies, as from a real unit at the wrong baud rate.
  :class:`ProbeHeadTcpServer` serves the same unit on ``socket://127.0.0.1:<port>``.
* :class:`ProbeFaults` scripts faults at run time: one-shot garble / truncate / drop / busy /
  delay, added latency, a per-channel forced marker, unsolicited frames (before the next reply);
  ``server.send_unsolicited()`` puts a frame on the line between requests and
  ``server.disconnect()`` makes the port vanish.
"""

from __future__ import annotations

import collections
import enum
import math
import os
import select
import socket
import termios
import threading
import time
import tty
from typing import Callable

import numpy as np

from drivers.probe_dialects import check_line_settings, get_dialect
from drivers.probe_protocol import (
    MAX_REQUEST_BYTES,
    ChannelStatus,
)
from simulators.probe_contact import touch_readings
from simulators.probe_dialect_units import KeyenceUnit, MitutoyoUnit, StationUnit
from station.core.probe.geometry import ProbeHeadGeometry, default_probe_head

__all__ = ["ProbeHeadPhysics", "FaultKind", "ProbeFaults", "ProbeHeadServer",
           "ProbeHeadTcpServer"]

_STATUS_VALUE = {
    ChannelStatus.OVER_RANGE: math.inf,
    ChannelStatus.UNDER_RANGE: -math.inf,
    ChannelStatus.INVALID: math.nan,
}


class ProbeHeadPhysics:
    """True probe head: ``readings(M_true)`` -> ``(n,)`` mm, +inf/-inf/NaN markers, in the
    geometry's probe order; :meth:`channel_values` is what the interface unit shows, channel by
    channel (the head's channel numbers, each value divided by its probe's scale factor).

    ``M_true`` is the true pose of MPKS in MKKS, or None when no cube is near (all INVALID).

    Per-probe faults (``probe``: its index in the geometry or its id):

    * :meth:`inject_stuck`: the plunger sticks, its reading freezes (at ``value_mm``, or at the
      reading of the next snapshot);
    * :meth:`inject_debris`: debris on the tip adds ``offset_mm`` to its reading, for the next
      ``touches`` touches (None: until cleared). A touch begins whenever the head's true pose
      changes (the robot moved); the snapshots of one touch share it.
    """

    def __init__(self, geometry: ProbeHeadGeometry | None = None, noise_mm: float = 0.0005,
                 quantum_mm: float = 0.0001, seed: int | None = 0) -> None:
        self.geometry = geometry if geometry is not None else default_probe_head()
        self.noise_mm = noise_mm
        self.quantum_mm = quantum_mm
        self._rng = np.random.default_rng(seed)
        self._lock = threading.Lock()
        self._stuck: dict[int, float | None] = {}
        self._debris: dict[int, list] = {}  # probe -> [offset_mm, touches left (None: forever)]
        self._last_M: np.ndarray | None = None
        #: touches seen so far (a change of the true pose starts one)
        self.touches = 0

    @property
    def n_channels(self) -> int:
        """Channels the unit serves: up to the highest channel the head uses."""
        return int(np.max(self.geometry.probe_channels))

    def _index(self, probe: int | str) -> int:
        if isinstance(probe, str):
            if probe not in self.geometry.probe_ids:
                raise ValueError(f"no probe {probe!r}; the head has {list(self.geometry.probe_ids)}")
            return self.geometry.probe_ids.index(probe)
        if not 0 <= int(probe) < self.geometry.n_probes:
            raise ValueError(f"probe index {probe} outside 0 … {self.geometry.n_probes - 1}")
        return int(probe)

    def inject_stuck(self, probe: int | str, value_mm: float | None = None) -> None:
        """Freeze a probe's reading at ``value_mm`` (None: at its next reading) until cleared."""
        with self._lock:
            self._stuck[self._index(probe)] = None if value_mm is None else float(value_mm)

    def inject_debris(self, probe: int | str, offset_mm: float, touches: int | None = None) -> None:
        """Add ``offset_mm`` to a probe's reading for the next ``touches`` touches (None: until
        cleared)."""
        if touches is not None and touches < 1:
            raise ValueError("touches must be >= 1 (or None: permanent)")
        with self._lock:
            self._debris[self._index(probe)] = [float(offset_mm), touches]

    def clear_faults(self) -> None:
        with self._lock:
            self._stuck.clear()
            self._debris.clear()

    def readings(self, M_true: np.ndarray | None, rng: np.random.Generator | None = None) -> np.ndarray:
        """``rng``: draw the noise from this generator (the cell keys it to the robot's state
        so that a repeated command sequence reproduces its readings exactly)."""
        n = self.geometry.n_probes
        if M_true is None:
            # Nothing under the head: each spring-loaded plunger rests at its extended stop, past
            # the far end of its measuring range (a positive reading is further extended), so the
            # unit shows over range there, as a real head parked in the air does, not "invalid".
            return np.full(n, np.inf)
        g = self.geometry  # the simulator's own contact physics, not the station's solver (probe_contact.py)
        exact = touch_readings(g.mount_points, g.directions, g.faces, g.tip_radii, g.strokes, g.cube_edge_mm, M_true)
        noisy = exact + (self._rng if rng is None else rng).normal(0.0, self.noise_mm, n)
        noisy = self._faulted(np.asarray(M_true, dtype=float), noisy)
        half = self.geometry.strokes / 2.0
        # Noise may carry a reading just across the stroke end; markers stay markers.
        out = np.where(noisy > half, np.inf, np.where(noisy < -half, -np.inf, noisy))
        if self.quantum_mm > 0:
            out = np.where(np.isfinite(out), np.round(out / self.quantum_mm) * self.quantum_mm, out)
        return out

    def _faulted(self, M: np.ndarray, values: np.ndarray) -> np.ndarray:
        with self._lock:
            if self._last_M is None or not np.array_equal(M, self._last_M):
                self.touches += 1
                self._last_M = M.copy()
                for k in list(self._debris):
                    left = self._debris[k][1]
                    if left is not None:
                        if left <= 0:
                            del self._debris[k]
                        else:
                            self._debris[k][1] = left - 1
            if not (self._stuck or self._debris):
                return values
            out = values.copy()
            for k, (offset, _) in self._debris.items():
                out[k] += offset
            for k, frozen in self._stuck.items():
                if frozen is None:
                    self._stuck[k] = frozen = float(out[k])
                out[k] = frozen
            return out

    def channel_values(self, M_true: np.ndarray | None, rng: np.random.Generator | None = None) -> np.ndarray:
        """``(n_channels,)``: what the unit displays on each channel (probe reading / scale),
        NaN (invalid) on a channel no probe uses."""
        r = self.readings(M_true, rng)
        g = self.geometry
        out = np.full(self.n_channels, np.nan)
        out[g.probe_channels - 1] = np.where(np.isfinite(r), r / g.probe_scales, r)
        return out


class FaultKind(enum.Enum):
    GARBLE = "garble"      # next reply: a byte gets its top bit set (as a UART glitch would)
    TRUNCATE = "truncate"  # next reply: only its first half, no CR LF
    DROP = "drop"          # next reply: not sent at all (lost)
    BUSY = "busy"          # next request: answered ER,<cmd>,05 instead
    DELAY = "delay"        # next reply: held back (0.5 s, or the seconds given to inject_delay)
    UNSOLICITED = "unsolicited"  # next reply: preceded by a frame nobody asked for


class ProbeFaults:
    """Fault script, safe to change from the test thread while the server runs."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._queue: collections.deque[tuple[FaultKind, object]] = collections.deque()
        self._forced: dict[int, ChannelStatus] = {}
        self.latency_s = 0.0  # added before every reply

    def inject(self, kind: FaultKind, count: int = 1) -> None:
        """Queue ``count`` one-shot faults, applied to the next replies in order
        (``DELAY`` holds a reply back by 0.5 s; see :meth:`inject_delay`)."""
        default = {FaultKind.DELAY: 0.5, FaultKind.UNSOLICITED: b"ID,NOBODY-ASKED,0.0,06\r\n"}
        with self._lock:
            self._queue.extend([(kind, default.get(kind))] * count)

    def inject_delay(self, seconds: float, count: int = 1) -> None:
        """The next ``count`` replies are each held back by ``seconds`` (a one-off stall of the
        unit, unlike :attr:`latency_s` which delays every reply). Later requests queue up
        behind it and are answered in order, as a real unit would."""
        if not seconds >= 0:
            raise ValueError("delay must be >= 0 seconds")
        with self._lock:
            self._queue.extend([(FaultKind.DELAY, float(seconds))] * count)

    def inject_unsolicited(self, frame: bytes, count: int = 1) -> None:
        """The next ``count`` replies are each preceded by ``frame`` (sent as is)."""
        with self._lock:
            self._queue.extend([(FaultKind.UNSOLICITED, bytes(frame))] * count)

    def force_status(self, channel: int, status: ChannelStatus | None) -> None:
        """Make a channel report a marker (a probe fault) until called again with None."""
        with self._lock:
            if status is None or status is ChannelStatus.OK:
                self._forced.pop(channel, None)
            else:
                self._forced[channel] = status

    def clear(self) -> None:
        with self._lock:
            self._queue.clear()
            self._forced.clear()
            self.latency_s = 0.0

    @property
    def pending(self) -> int:
        with self._lock:
            return len(self._queue)

    def _next(self) -> tuple[FaultKind, object] | tuple[None, None]:
        with self._lock:
            return self._queue.popleft() if self._queue else (None, None)

    def _forced_now(self) -> dict[int, ChannelStatus]:
        with self._lock:
            return dict(self._forced)


def _garble(reply: bytes) -> bytes:
    """What a receiver at another baud rate or framing makes of ``reply``: every byte a
    different one with the top bit set, the CR LF included (so no line ever ends)."""
    return bytes(((b * 37 + 0x5B) & 0x7F) | 0x80 for b in reply)


def _termios_exposure(fd: int) -> tuple[bool, bool]:
    """Whether this pty keeps CSIZE and PARENB as set (Linux forces CS8, clears PARENB)."""
    attrs = termios.tcgetattr(fd)
    trial = list(attrs)
    trial[2] = (attrs[2] & ~termios.CSIZE) | termios.CS7 | termios.PARENB
    try:
        termios.tcsetattr(fd, termios.TCSANOW, trial)
        back = termios.tcgetattr(fd)[2]
    except termios.error:  # a pty that refuses the framing outright exposes none of it
        return False, False
    finally:
        termios.tcsetattr(fd, termios.TCSANOW, attrs)
    return (back & termios.CSIZE) == termios.CS7, bool(back & termios.PARENB)


def _split_lines(buf: bytearray) -> list[bytes]:
    """Pop complete request lines (CR or CR LF terminated) from ``buf``; a stray LF left by a
    CR LF is dropped at the start of the next line. Over-long garbage is cut off as one line."""
    lines = []
    while True:
        while buf[:1] == b"\n":
            del buf[:1]
        idx = buf.find(b"\r")
        if idx < 0:
            if len(buf) > MAX_REQUEST_BYTES:
                lines.append(bytes(buf))  # answered ER,??,.. like a unit whose buffer overran
                buf.clear()
            return lines
        lines.append(bytes(buf[:idx]))
        del buf[: idx + 1]


class ProbeHeadServer:
    """The unit on a pseudo-terminal, served by a background thread.

    ``snapshot_source()`` returns the channel values [mm] at the moment of the call (+inf over
    range, -inf under range, NaN invalid); it is called once per request that needs readings,
    so an ``M0`` reply is one consistent snapshot (``n_channels=None``: called once here to
    count them). ``pace``: hold replies to the time the bytes would take at ``baudrate``
    (start + data + parity + stop bits per byte), including the request's own transfer.
    ``protocol``: the dialect the unit speaks; ``baudrate`` / ``bytesize`` / ``parity``: the
    unit's own line settings (None: the dialect's factory default; station-ascii 38400 8N1,
    keyence-dl-rs1a 9600 8N1). ``refresh_s`` / ``writable``: the DL-RS1A's buffer refresh and
    read/write switch. ``garble_on_mismatch``: garble replies when the pty shows other settings.
    """

    def __init__(self, snapshot_source: Callable[[], np.ndarray], n_channels: int | None = None,
                 baudrate: int | None = None, pace: bool = True, model: str = "SIM-PH6",
                 firmware: str = "1.0.0", faults: ProbeFaults | None = None, *, protocol: str = "station-ascii",
                 bytesize: int | None = None, parity: str | None = None, refresh_s: float = 0.02,
                 writable: bool = False, garble_on_mismatch: bool = True) -> None:
        if n_channels is None:
            n_channels = len(np.asarray(snapshot_source()))
        self.faults = faults if faults is not None else ProbeFaults()
        self.dialect = get_dialect(protocol)
        self.line = check_line_settings(self.dialect, baudrate, bytesize, parity)
        self.unit: StationUnit | KeyenceUnit | MitutoyoUnit
        if self.dialect.name == "keyence-dl-rs1a":
            self.unit = KeyenceUnit(snapshot_source, n_channels, self.faults, refresh_s=refresh_s, writable=writable)
        elif self.dialect.name == "mitutoyo-ga":
            self.unit = MitutoyoUnit(snapshot_source, n_channels, self.faults)
        else:
            self.unit = StationUnit(snapshot_source, n_channels, model, firmware, self.faults)
        baudrate = self.line.baudrate
        self.baudrate = baudrate
        self.pace = pace
        self.garble_on_mismatch = garble_on_mismatch
        #: replies garbled because the station's line settings differed from the unit's
        self.garbled_replies = 0
        self._exposes = (False, False)  # (data bits, parity) visible in the pty's termios
        self.failure: BaseException | None = None
        #: requests fully answered (or deliberately dropped); tests wait on it
        self.requests_done = 0
        self._byte_s = self.line.bits_per_byte / baudrate
        self._stop = threading.Event()
        self._ready = threading.Event()
        self._thread: threading.Thread | None = None
        self._wake_r, self._wake_w = -1, -1
        self._fd = -1          # the fd the loop reads and writes
        self._write_lock = threading.Lock()  # replies and send_unsolicited() never interleave
        #: unsolicited frames written so far (send_unsolicited and UNSOLICITED faults)
        self.unsolicited_sent = 0
        self._closed = False
        self.port = ""

    # ---------------------------------------------------------------- transport hooks

    def _open(self) -> None:
        master, slave = os.openpty()
        # Raw mode: no echo, no CR/LF translation - the bytes are the protocol.
        tty.setraw(slave)
        self._exposes = _termios_exposure(slave)
        # Keep our slave fd open so the master does not see EIO whenever the driver closes
        # its port; the pty only dies when disconnect()/stop() closes the master.
        self._slave = slave
        os.set_blocking(master, False)
        self._fd = master
        self.port = os.ttyname(slave)

    def _wait_client(self) -> bool:
        return True  # a pty is always "connected"

    def _line_differs(self) -> bool:
        """The station's settings as the pty shows them differ from the unit's own."""
        slave = getattr(self, "_slave", -1)
        if not self.garble_on_mismatch or slave is None or slave < 0:
            return False
        try:
            attrs = termios.tcgetattr(slave)
        except termios.error:
            return False
        expected = getattr(termios, f"B{self.line.baudrate}", None)
        if expected is not None and attrs[5] != expected:
            return True
        cflag = attrs[2]
        if self._exposes[0] and (cflag & termios.CSIZE) != (termios.CS7 if self.line.bytesize == 7 else termios.CS8):
            return True
        if self._exposes[1]:
            shown = "none" if not cflag & termios.PARENB else "odd" if cflag & termios.PARODD else "even"
            return shown != self.line.parity
        return False

    def _close(self) -> None:
        for fd in (self._fd, getattr(self, "_slave", -1)):
            if fd >= 0:
                os.close(fd)
        self._fd = -1
        self._slave = -1

    # ---------------------------------------------------------------- lifetime

    def start(self) -> "ProbeHeadServer":
        if self._thread is not None:
            raise RuntimeError("server already started")
        self._open()
        self._wake_r, self._wake_w = os.pipe()
        self._thread = threading.Thread(target=self._run, name="probe-head-sim", daemon=True)
        self._thread.start()
        if not self._ready.wait(5.0):
            raise RuntimeError("probe-head simulator thread did not start")
        return self

    def stop(self) -> None:
        """Stop serving and close the port; re-raises a failure of the serving thread."""
        if self._thread is not None and not self._closed:
            self._stop.set()
            os.write(self._wake_w, b"x")
            self._thread.join(5.0)
            if self._thread.is_alive():
                raise RuntimeError("probe-head simulator thread did not stop")
            self._close()
            os.close(self._wake_r)
            os.close(self._wake_w)
            self._closed = True
        if self.failure is not None:
            raise RuntimeError("probe-head simulator failed while serving") from self.failure

    def disconnect(self) -> None:
        """Fault: the unit vanishes (pty master closed); the driver sees the port gone."""
        self.stop()

    def __enter__(self) -> "ProbeHeadServer":
        return self.start()

    def __exit__(self, *exc_info) -> None:
        self.stop()

    # ---------------------------------------------------------------- serving

    def _run(self) -> None:
        self._ready.set()
        try:
            buf = bytearray()
            while not self._stop.is_set():
                if not self._wait_client():
                    continue
                ready, _, _ = select.select([self._fd, self._wake_r], [], [], 1.0)
                if self._wake_r in ready or self._stop.is_set():
                    return
                if not ready:
                    continue
                try:
                    data = os.read(self._fd, 4096)
                except BlockingIOError:
                    continue
                except ConnectionResetError:
                    data = b""
                if not data:
                    self._client_gone()
                    buf.clear()
                    continue
                received_at = time.monotonic()
                buf += data
                lines = _split_lines(buf)
                wire_bytes = 0
                for line in lines:
                    # Request transfer time: the pty delivered instantly, a wire would not.
                    wire_bytes += len(line) + 1
                    self._pace_until(received_at + wire_bytes * self._byte_s)
                    self._reply(self.unit.handle(line), line)
        except BaseException as exc:  # recorded and re-raised by stop(), never dropped
            self.failure = exc

    def _client_gone(self) -> None:
        raise ConnectionError("pty master read returned EOF")

    def _pace_until(self, deadline: float) -> None:
        if self.pace:
            delay = deadline - time.monotonic()
            if delay > 0:
                self._stop.wait(delay)

    def send_unsolicited(self, frame: bytes) -> None:
        """Put ``frame`` on the line now, between requests (a unit that babbles, a second
        device on the bus, line noise that happens to look like a frame)."""
        if self._thread is None or self._closed or self._fd < 0:
            raise RuntimeError("server not running, or no client connected")
        self._send(bytes(frame))
        self.unsolicited_sent += 1

    def _reply(self, reply: bytes | None, line: bytes) -> None:
        fault, arg = self.faults._next()
        if fault is FaultKind.DELAY and isinstance(arg, float):
            self._stop.wait(arg)
        elif fault is FaultKind.UNSOLICITED and isinstance(arg, bytes):
            self._send(arg)
            self.unsolicited_sent += 1
        elif fault is FaultKind.BUSY:
            reply = self.unit.busy_reply(line)
        if reply is None:  # a unit that stays silent (no such indicator, busy without a reply)
            self.requests_done += 1
            return
        if fault is FaultKind.DROP:
            self.requests_done += 1
            return
        elif fault is FaultKind.TRUNCATE:
            reply = reply[: max(1, len(reply) // 2)]
        elif fault is FaultKind.GARBLE:
            b = bytearray(reply)
            b[3] |= 0x80  # the first field starts at index 3 in every reply
            reply = bytes(b)
        if self._line_differs():
            reply = _garble(reply)
            self.garbled_replies += 1
        if self.faults.latency_s > 0:
            self._stop.wait(self.faults.latency_s)
        self._send(reply)
        self.requests_done += 1

    def _send(self, data: bytes) -> None:
        """Write paced in small chunks: a chunk goes out when its last byte would have arrived."""
        with self._write_lock:
            start = time.monotonic()
            chunk = 8 if self.pace else len(data)
            for i in range(0, len(data), chunk):
                part = data[i: i + chunk]
                self._pace_until(start + (i + len(part)) * self._byte_s)
                try:
                    os.write(self._fd, part)
                except (BrokenPipeError, ConnectionResetError):
                    return  # TCP client went away; the next read notices and waits for another
                except BlockingIOError:
                    return  # nobody is draining the line: a real UART would lose these bytes


class ProbeHeadTcpServer(ProbeHeadServer):
    """The same unit on TCP (``.url`` = ``socket://127.0.0.1:<port>``), one client at a time,
    like a serial-to-Ethernet adapter."""

    def _open(self) -> None:
        self._listener = socket.create_server(("127.0.0.1", 0))
        self._listener.setblocking(False)
        host, port = self._listener.getsockname()[:2]
        self.port = f"socket://{host}:{port}"
        self._conn: socket.socket | None = None
        self._fd = -1

    @property
    def url(self) -> str:
        return self.port

    def _wait_client(self) -> bool:
        if self._conn is not None:
            return True
        watched: list[socket.socket | int] = [self._listener, self._wake_r]
        ready, _, _ = select.select(watched, [], [], 1.0)
        if self._listener in ready:
            conn, _ = self._listener.accept()
            conn.setblocking(False)
            # Paced replies go out in small chunks; Nagle + delayed ACK would add ~40 ms each.
            conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            self._conn = conn
            self._fd = conn.fileno()
            return True
        return False

    def _client_gone(self) -> None:
        assert self._conn is not None
        self._conn.close()
        self._conn = None
        self._fd = -1

    def _close(self) -> None:
        if self._conn is not None:
            self._conn.close()
            self._conn = None
        self._listener.close()
        self._fd = -1
