"""Driver for the probe-head serial unit (protocol: :mod:`drivers.probe_protocol`).

Opens any pyserial URL (``/dev/ttyUSB0``, a pseudo-terminal, ``socket://host:port``,
``rfc2217://...``) or wraps an already-open serial-like object (tests use a scripted fake).

Transaction rules (the sequence rule of ``docs/protocols.md``), each for a reason seen in the
field:

* stale input is flushed before every request;
* after a timeout the line is out of step: a reply may still be on its way and, for ``M0``,
  would look exactly like the answer to the next request. Before the next request the driver
  therefore sends ``ID`` as a fence and discards every line up to the fence's answer (the unit
  answers strictly in order, so every late reply comes before it); only then is the request
  sent. A fence that is not answered in time leaves the line out of step (ProbeTimeout);
* while waiting for a reply, complete lines that do not name the request (another command's
  echo, an unsolicited frame) are discarded, counted and logged, never parsed as the answer;
* ``read_until`` returns a partial line on timeout without raising, so the terminator is
  checked and a missing one is a :class:`ProbeTimeout`;
* only read-only commands (the protocol table says which) are retried, a bounded number of
  times; zero/preset change the unit's state and are never repeated blindly;
* every timeout, retry, resynchronisation and discarded frame is logged (logger
  ``drivers.probe_head``) and counted in :attr:`ProbeHead.stats`: a retried snapshot is a
  fresh reading, so a run with retries does not repeat a run without them bit for bit;
* every serial-layer exception becomes :class:`ProbeDisconnected` (chained, never swallowed).

The driver knows nothing of the station: channel values are plain millimetres.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, fields
from typing import Protocol

import numpy as np
import serial

from drivers.probe_protocol import (
    COMMANDS,
    REPLY_TERMINATOR,
    RESYNC_COMMAND,
    ChannelStatus,
    DeviceInfo,
    ProbeDeviceError,
    ProbeDisconnected,
    ProbeError,
    ProbeFrameError,
    ProbeOutOfRange,
    ProbeSpreadError,
    ProbeTimeout,
    format_request,
    parse_ack,
    parse_id,
    parse_m0,
    parse_ms,
    reply_names,
)

try:  # tcflush on a pty whose master has gone raises termios.error, not SerialException
    import termios

    _TERMIOS_ERRORS: tuple[type[BaseException], ...] = (termios.error,)
except ImportError:  # pragma: no cover - not on POSIX
    _TERMIOS_ERRORS = ()

__all__ = [
    "ProbeHead",
    "ProbeSnapshot",
    "LinkStats",
    "ChannelStatus",
    "DeviceInfo",
    "ProbeError",
    "ProbeTimeout",
    "ProbeFrameError",
    "ProbeDeviceError",
    "ProbeSpreadError",
    "ProbeDisconnected",
    "ProbeOutOfRange",
]

log = logging.getLogger(__name__)

_PORT_ERRORS = (serial.SerialException, OSError) + _TERMIOS_ERRORS
# The longest legal reply: "M0," + 15 * 9 value characters + 14 commas + CR LF, with margin.
_MAX_REPLY_BYTES = 256
# Foreign lines discarded while waiting for one reply before the wait is given up (a babbling
# line must not keep a transaction alive forever).
_MAX_DISCARDED_LINES = 16
_RESYNC_FRAME = format_request(RESYNC_COMMAND)


@dataclass
class LinkStats:
    """What the line did since the port was opened (counters only grow).

    ``timeouts``: transactions without a complete reply; ``retries``: repeated read-only
    requests; ``resyncs``: ``ID`` fences sent after a timeout; ``discarded_frames``: stale or
    unsolicited lines dropped (flushed before a request, or not naming the request);
    ``discarded_bytes``: their bytes.
    """

    timeouts: int = 0
    retries: int = 0
    resyncs: int = 0
    discarded_frames: int = 0
    discarded_bytes: int = 0

    def copy(self) -> "LinkStats":
        return LinkStats(**{f.name: getattr(self, f.name) for f in fields(self)})


class SerialLike(Protocol):
    def write(self, data: bytes) -> int | None: ...
    def read_until(self, expected: bytes = ..., size: int | None = ...) -> bytes: ...
    def reset_input_buffer(self) -> None: ...
    def close(self) -> None: ...


@dataclass(frozen=True, eq=False)
class ProbeSnapshot:
    """All channels at one instant.

    ``values_mm``: shape ``(n,)``, read-only, NaN where ``status`` is not OK.
    ``raw``: the reply frame(s) exactly as received (several, concatenated, for an average).
    ``timestamp``: ``time.time()`` when the request left the PC (the unit latches on receipt);
    for an average, the mean over the snapshots.
    """

    values_mm: np.ndarray
    status: tuple[ChannelStatus, ...]
    raw: bytes
    timestamp: float

    @property
    def all_ok(self) -> bool:
        return all(s is ChannelStatus.OK for s in self.status)

    def require_ok(self) -> None:
        """Raise :class:`ProbeOutOfRange` naming every channel that is not OK."""
        bad: dict[int, ChannelStatus] = {i: s for i, s in enumerate(self.status) if s is not ChannelStatus.OK}
        if bad:
            raise ProbeOutOfRange(bad)


def _frozen(a: np.ndarray) -> np.ndarray:
    a = np.array(a, dtype=float)
    a.flags.writeable = False
    return a


class ProbeHead:
    """One probe-head unit on one serial line. Not thread-safe: one owner at a time."""

    def __init__(self, url: str, baudrate: int = 38400, timeout: float = 0.5, retries: int = 2):
        try:
            port = serial.serial_for_url(url, baudrate=baudrate, timeout=timeout)
        except _PORT_ERRORS as exc:
            raise ProbeDisconnected(
                f"cannot open probe unit at {url!r}: {exc}; check the device path or URL, that "
                "the unit is powered and cabled, and that no other program holds the port"
            ) from exc
        self._init(port, url, timeout, retries)

    @classmethod
    def from_port(cls, port: SerialLike, timeout: float = 0.5, retries: int = 2,
                  name: str = "<port>") -> "ProbeHead":
        """Wrap an already-open serial-like object (the port's own timeout applies)."""
        self = cls.__new__(cls)
        self._init(port, name, timeout, retries)
        return self

    def _init(self, port: SerialLike, name: str, timeout: float, retries: int) -> None:
        if retries < 0:
            raise ValueError("retries must be >= 0")
        self._port = port
        self._name = name
        self._timeout = timeout
        self._retries = retries
        self._channels: int | None = None  # learnt from ID or the first M0
        self._in_step = True  # False after a timeout: fence with ID before the next request
        self.stats = LinkStats()
        self.info: DeviceInfo | None = None

    # ---------------------------------------------------------------- lifetime

    def close(self) -> None:
        try:
            self._port.close()
        except _PORT_ERRORS as exc:
            raise ProbeDisconnected(f"closing {self._name} failed: {exc}") from exc

    def __enter__(self) -> "ProbeHead":
        return self

    def __exit__(self, *exc_info) -> None:
        self.close()

    @property
    def channels(self) -> int | None:
        return self._channels

    # ---------------------------------------------------------------- transport

    def _exchange(self, frame: bytes, name: str) -> tuple[bytes, float]:
        """One request/reply; returns the reply line (with CR LF) and the send time."""
        try:
            if not self._in_step:
                self._resync(frame)
            self._flush()
            sent_at = time.time()
            self._port.write(frame)
            line = self._read_reply(frame, name)
        except _PORT_ERRORS as exc:
            raise ProbeDisconnected(
                f"serial port {self._name} failed during {frame.strip()!r}: {exc}; the port has "
                "gone (USB adapter unplugged, unit switched off?) - reconnect and reopen it"
            ) from exc
        return line, sent_at

    def _flush(self) -> None:
        """Discard buffered input (counted when the port can tell how much there was)."""
        pending = getattr(self._port, "in_waiting", 0)
        if isinstance(pending, int) and pending > 0:
            self.stats.discarded_frames += 1
            self.stats.discarded_bytes += pending
            log.warning("%s: discarded %d stale byte(s) before a request (a late reply or an "
                        "unsolicited frame)", self._name, pending)
        self._port.reset_input_buffer()

    def _discard(self, line: bytes, waiting_for: str) -> None:
        self.stats.discarded_frames += 1
        self.stats.discarded_bytes += len(line)
        log.warning("%s: discarded %r while waiting for the reply to %s: it does not answer "
                    "that request (late reply or unsolicited frame)", self._name, line[:60],
                    waiting_for)

    def _lost_step(self, frame: bytes, line: bytes) -> ProbeTimeout:
        """A wait ended without a complete reply: the line is out of step until a fence."""
        self._in_step = False
        self.stats.timeouts += 1
        log.warning("%s: no complete reply to %r within %s s (got %r); the line will be "
                    "resynchronised with %s before the next request", self._name, frame.strip(),
                    self._timeout, line[:40], RESYNC_COMMAND)
        if line:
            return ProbeTimeout(
                f"incomplete reply to {frame.strip()!r} from {self._name} within "
                f"{self._timeout} s ({line[:40]!r}): check the baud rate and the cable"
            )
        return ProbeTimeout(
            f"no reply to {frame.strip()!r} from {self._name} within {self._timeout} s: check "
            "that the unit is on, the cable (TX/RX crossed?) and the baud rate"
        )

    def _read_reply(self, frame: bytes, name: str) -> bytes:
        """Read lines until one names ``name``; discard the others (bounded)."""
        deadline = time.monotonic() + self._timeout
        for _ in range(_MAX_DISCARDED_LINES):
            line = self._port.read_until(REPLY_TERMINATOR, _MAX_REPLY_BYTES)
            if not line.endswith(REPLY_TERMINATOR):
                raise self._lost_step(frame, line)
            if reply_names(line, name):
                return line
            self._discard(line, name)
            if time.monotonic() >= deadline:
                raise self._lost_step(frame, b"")
        raise self._lost_step(frame, b"")

    def _resync(self, frame: bytes) -> None:
        """The fence: send ID and discard every line up to its answer. Raises ProbeTimeout
        (line still out of step) if the unit does not answer it in time."""
        self.stats.resyncs += 1
        self._flush()
        self._port.write(_RESYNC_FRAME)
        deadline = time.monotonic() + self._timeout
        for _ in range(_MAX_DISCARDED_LINES):
            line = self._port.read_until(REPLY_TERMINATOR, _MAX_REPLY_BYTES)
            if not line.endswith(REPLY_TERMINATOR):
                break
            if reply_names(line, RESYNC_COMMAND):
                self._in_step = True
                log.info("%s: line resynchronised (%s answered)", self._name, RESYNC_COMMAND)
                return
            self._discard(line, f"{RESYNC_COMMAND} (resynchronisation)")
            if time.monotonic() >= deadline:
                break
        self.stats.timeouts += 1
        raise ProbeTimeout(
            f"{self._name} did not answer the resynchronisation request {RESYNC_COMMAND} within "
            f"{self._timeout} s after an earlier timeout, so {frame.strip()!r} was not sent: "
            "check that the unit is on, the cable and the baud rate"
        )

    def _transact(self, name: str, parse, *args):
        """Send a command and parse its reply, retrying read-only commands on transient
        faults (timeout, garbled frame, busy). Returns ``(parsed, raw, sent_at)``."""
        frame = format_request(name, *args)
        attempts = 1 + (self._retries if COMMANDS[name].read_only else 0)
        last: ProbeError | None = None
        for attempt in range(attempts):
            if attempt:
                self.stats.retries += 1
                log.warning("%s: repeating %s (attempt %d of %d) after: %s", self._name, name,
                            attempt + 1, attempts, last)
            try:
                raw, sent_at = self._exchange(frame, name)
                return parse(raw), raw, sent_at
            except (ProbeTimeout, ProbeFrameError) as exc:
                last = exc
            except ProbeDeviceError as exc:
                if not exc.retryable:
                    raise
                last = exc
        assert last is not None
        if isinstance(last, ProbeDeviceError):
            raise last
        if COMMANDS[name].read_only:
            raise type(last)(f"{last} (gave up after {attempts} attempts)") from last
        raise type(last)(
            f"{last}; {name} changes the unit's state and was not repeated - read the "
            "channel to see whether it took effect"
        ) from last

    # ---------------------------------------------------------------- commands

    def identify(self) -> DeviceInfo:
        info, _, _ = self._transact("ID", parse_id)
        self.info = info
        self._channels = info.channels
        return info

    def read_all(self) -> ProbeSnapshot:
        (values, status), raw, sent_at = self._transact(
            "M0", lambda line: parse_m0(line, self._channels))
        if self._channels is None:
            self._channels = len(status)
        return ProbeSnapshot(_frozen(values), status, raw, sent_at)

    def read_channel(self, channel: int) -> tuple[float, ChannelStatus]:
        """One channel (0-based) -> ``(value_mm, status)``, NaN unless OK."""
        self._check_channel(channel)
        (value, status), _, _ = self._transact("MS", lambda line: parse_ms(line, channel), channel)
        return value, status

    def read_averaged(self, n: int, max_spread_mm: float) -> ProbeSnapshot:
        """Mean of ``n`` snapshots.

        A channel that is not OK in some snapshot is reported with the first such status and
        NaN. For OK channels the peak-to-peak spread must stay within ``max_spread_mm``, else
        :class:`ProbeSpreadError` (for the worst channel).
        """
        if n < 1:
            raise ValueError("n must be >= 1")
        snaps = [self.read_all() for _ in range(n)]
        values = np.stack([s.values_mm for s in snaps])  # (n, channels)
        status = []
        for ch in range(values.shape[1]):
            bad = [s.status[ch] for s in snaps if s.status[ch] is not ChannelStatus.OK]
            status.append(bad[0] if bad else ChannelStatus.OK)
        ok = np.array([s is ChannelStatus.OK for s in status])
        spread = np.where(ok, np.ptp(np.where(ok, values, 0.0), axis=0), 0.0)
        worst = int(np.argmax(spread)) if spread.size else 0
        if spread.size and spread[worst] > max_spread_mm:
            raise ProbeSpreadError(worst, float(spread[worst]), max_spread_mm)
        mean = np.where(ok, values.mean(axis=0), np.nan)
        return ProbeSnapshot(
            _frozen(mean), tuple(status), b"".join(s.raw for s in snaps),
            float(np.mean([s.timestamp for s in snaps])),
        )

    def zero(self, channel: int) -> None:
        """Make the channel's present reading 0.000 0 mm (never retried)."""
        self._check_channel(channel)
        self._transact("ZS", lambda line: parse_ack(line, "ZS", channel), channel)

    def preset(self, channel: int, value_mm: float) -> None:
        """Make the channel's present reading ``value_mm`` (never retried)."""
        self._check_channel(channel)
        self._transact("PS", lambda line: parse_ack(line, "PS", channel), channel, value_mm)

    def clear_zero(self, channel: int) -> None:
        """Remove a zero or preset: the channel reads its raw value again (never retried)."""
        self._check_channel(channel)
        self._transact("ZC", lambda line: parse_ack(line, "ZC", channel), channel)

    def _check_channel(self, channel: int) -> None:
        limit = self._channels
        if not isinstance(channel, (int, np.integer)) or channel < 0 or (
                limit is not None and channel >= limit):
            raise ValueError(
                f"channel {channel!r} outside 0..{(limit or 15) - 1} for {self._name}")
