"""Driver for a probe-head serial unit, in any dialect of :mod:`drivers.probe_dialects`.

``ProbeHead(url, baudrate, timeout, retries, dialect="station-ascii", bytesize=None,
parity=None, channels=None, valid_range_mm=None, settle_tolerance_mm=0.005)``: the line
settings are checked against the dialect before the port opens (ProbeLineSettingsError names
what the unit offers); None takes the dialect's factory default. Opens any pyserial URL
(``/dev/ttyUSB0``, a pseudo-terminal, ``socket://host:port``) or wraps an already-open
serial-like object (:meth:`ProbeHead.from_port`; tests use a scripted fake).

Transaction rules (the sequence rule of ``docs/protocols.md``), each for a reason seen in the
field:

* stale input is flushed before every request;
* after a timeout the line is out of step: a late reply would look exactly like the answer to
  the next request. Before the next request the driver sends the dialect's harmless read-only
  fence (``ID`` for station-ascii, ``M0`` for the DL-RS1A, ``GA01`` for Mitutoyo) and discards
  every line up to its answer; a fence not answered in time leaves the line out of step;
* complete lines that do not name the request are discarded, counted and logged; one that is
  another dialect's answer to it (``ER,ID,00`` from a DL-RS1A) is :class:`ProbeDialectMismatch`;
* bytes no ASCII dialect sends (top bit set, control characters) in a reply that never ends
  are :class:`ProbeLineGarbled`, naming the line settings to check;
* only read-only requests are retried, a bounded number of times; an error the dialect's table
  marks "retry after wait" (DL-RS1A 22 and 02: amplifiers starting up) waits first;
* freshness (DL-RS1A): the unit returns buffered data refreshed every few tens of ms behind the
  amplifiers' response-time filter, so a reading is accepted only when two ``M0`` replies taken
  at least the refresh time apart agree within ``settle_tolerance_mm`` (``read_all``) or
  ``max_spread_mm`` (``read_averaged``), at most ``settle_attempts`` pairs, else ProbeUnsettled;
* every reading outside ``valid_range_mm`` (per channel, the probe's stroke / 2 / scale) or the
  dialect's value range is reported OVER_RANGE / UNDER_RANGE with NaN: never a measurement;
* every timeout, retry, fence and discarded frame is logged and counted in :attr:`stats`;
* every serial-layer exception becomes :class:`ProbeDisconnected` (chained, never swallowed).

The driver knows nothing of the station: channel values are plain millimetres.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, fields
from typing import Protocol, cast

import numpy as np
import serial

from drivers.probe_dialects import Dialect, Exchange, LineSettings, check_line_settings, dialects_claiming, get_dialect
from drivers.probe_protocol import (
    REPLY_TERMINATOR,
    ChannelStatus,
    DeviceInfo,
    ErrorAction,
    ProbeConfigError,
    ProbeDeviceError,
    ProbeDialectMismatch,
    ProbeDisconnected,
    ProbeError,
    ProbeFrameError,
    ProbeLineGarbled,
    ProbeOutOfRange,
    ProbeSpreadError,
    ProbeTimeout,
    ProbeUnsettled,
    format_request,
    parse_ack,
    parse_ms,
)

try:  # tcflush on a pty whose master has gone raises termios.error, not SerialException
    import termios

    _TERMIOS_ERRORS: tuple[type[BaseException], ...] = (termios.error,)
except ImportError:  # pragma: no cover - not on POSIX
    _TERMIOS_ERRORS = ()

__all__ = [
    "ProbeHead", "ProbeSnapshot", "LinkStats",
]

log = logging.getLogger(__name__)

_PORT_ERRORS = (serial.SerialException, OSError) + _TERMIOS_ERRORS
# The longest legal reply: "M0," + 15 * 9 value characters + 14 commas + CR LF, with margin.
_MAX_REPLY_BYTES = 256
# Foreign lines discarded while waiting for one reply before the wait is given up (a babbling
# line must not keep a transaction alive forever).
_MAX_DISCARDED_LINES = 16
_PARITY = {"none": serial.PARITY_NONE, "even": serial.PARITY_EVEN, "odd": serial.PARITY_ODD}


def _garbled(data: bytes) -> bool:
    """Bytes no ASCII dialect sends: the top bit set or control characters other than CR LF."""
    return any(b >= 0x80 or (b < 0x20 and b not in (0x0D, 0x0A)) for b in data)


@dataclass
class LinkStats:
    """What the line did since the port was opened (counters only grow).

    ``timeouts``: transactions without a complete reply; ``retries``: repeated read-only
    requests; ``resyncs``: fences sent after a timeout; ``unsettled``: snapshot pairs that did
    not agree (fresh-pair dialects); ``discarded_frames``: stale or
    unsolicited lines dropped (flushed before a request, or not naming the request);
    ``discarded_bytes``: their bytes.
    """

    timeouts: int = 0
    retries: int = 0
    resyncs: int = 0
    discarded_frames: int = 0
    discarded_bytes: int = 0
    unsettled: int = 0

    def copy(self) -> "LinkStats":
        return LinkStats(**{f.name: getattr(self, f.name) for f in fields(self)})


class SerialLike(Protocol):
    def write(self, data: bytes) -> int | None: ...
    def read_until(self, expected: bytes = ..., size: int | None = ...) -> bytes: ...
    def reset_input_buffer(self) -> None: ...
    def close(self) -> None: ...


class _BufferedPort(SerialLike, Protocol):
    """A port that tells how many bytes it holds and reads several at once (pyserial's)."""

    in_waiting: int

    def read(self, size: int = ...) -> bytes: ...


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
    """One probe-head unit on one serial line. Not thread-safe: one owner at a time.

    ``dialect``: a name of :data:`drivers.probe_dialects.DIALECTS` (``[devices] probe_protocol``);
    ``baudrate`` / ``bytesize`` / ``parity`` / ``stopbits``: None takes the dialect's factory
    default. ``channels``: the channel count, where known (a Mitutoyo line is scanned for it
    otherwise). ``valid_range_mm``: per channel (or one for all) the largest magnitude a reading
    may have and be a measurement (the probe's stroke / 2 / its scale); beyond it, the channel is
    OVER_RANGE / UNDER_RANGE. ``settle_tolerance_mm``, ``settle_attempts``: the freshness rule
    of fresh-pair dialects (DL-RS1A) for :meth:`read_all`; ``refresh_s``: the unit's buffer refresh
    time, the wait between the two snapshots of that rule (None: the dialect's, 50 ms for a DL-RS1A).
    """

    def __init__(self, url: str, baudrate: int | None = None, timeout: float = 0.5, retries: int = 2, *,
                 dialect: str | Dialect = "station-ascii", bytesize: int | None = None, parity: str | None = None,
                 stopbits: int | None = None, channels: int | None = None,
                 valid_range_mm: float | np.ndarray | list[float] | None = None,
                 settle_tolerance_mm: float = 0.005, settle_attempts: int = 5, refresh_s: float | None = None):
        d = get_dialect(dialect)
        line = check_line_settings(d, baudrate, bytesize, parity, stopbits)
        try:
            port = serial.serial_for_url(url, baudrate=line.baudrate, bytesize=line.bytesize,
                                         parity=_PARITY[line.parity], stopbits=line.stopbits, timeout=timeout)
        except _PORT_ERRORS as exc:
            raise ProbeDisconnected(
                f"cannot open probe unit at {url!r}: {exc}; check the device path or URL, that "
                "the unit is powered and cabled, and that no other program holds the port"
            ) from exc
        self._init(port, url, timeout, retries, d, line, channels, valid_range_mm, settle_tolerance_mm,
                   settle_attempts)
        if refresh_s is not None:  # the unit's own refresh time (amplifier count, response time)
            if not 0.0 <= refresh_s <= 10.0:
                raise ValueError(f"refresh_s must be 0 … 10 s, got {refresh_s}")
            self.refresh_s = float(refresh_s)

    @classmethod
    def from_port(cls, port: SerialLike, timeout: float = 0.5, retries: int = 2, name: str = "<port>", *,
                  dialect: str | Dialect = "station-ascii", line: LineSettings | None = None,
                  channels: int | None = None, valid_range_mm: float | np.ndarray | list[float] | None = None,
                  settle_tolerance_mm: float = 0.005, settle_attempts: int = 5) -> "ProbeHead":
        """Wrap an already-open serial-like object (the port's own timeout applies)."""
        d = get_dialect(dialect)
        self = cls.__new__(cls)
        self._init(port, name, timeout, retries, d, line or d.line.default, channels, valid_range_mm,
                   settle_tolerance_mm, settle_attempts)
        return self

    def _init(self, port: SerialLike, name: str, timeout: float, retries: int, dialect: Dialect,
              line: LineSettings, channels: int | None, valid_range_mm, settle_tolerance_mm: float,
              settle_attempts: int) -> None:
        #: the wait between the two snapshots of the freshness rule [s]: the dialect's refresh time
        self.refresh_s = dialect.refresh_s
        if retries < 0:
            raise ValueError("retries must be >= 0")
        if settle_attempts < 1:
            raise ValueError("settle_attempts must be >= 1")
        self._port = port
        self._name = name
        self._timeout = timeout
        self._retries = retries
        self.dialect = dialect
        self.line = line
        self._channels: int | None = channels  # learnt from ID, a scan or the first snapshot
        self._in_step = True  # False after a timeout: fence before the next request
        self._rx = b""  # bytes read after the last line (see _read_line)
        self._settle_tol = float(settle_tolerance_mm)
        self._settle_attempts = int(settle_attempts)
        self._valid: np.ndarray | None = None
        self.set_valid_range(valid_range_mm)
        self.stats = LinkStats()
        self.info: DeviceInfo | None = None

    def set_valid_range(self, limits_mm: float | np.ndarray | list[float] | None) -> None:
        """Largest magnitude of a measurement per channel (a scalar: every channel); None: only
        the dialect's own range. The station passes each channel's probe stroke / 2 / scale."""
        self._valid = None if limits_mm is None else np.atleast_1d(np.asarray(limits_mm, dtype=float))

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

    def _exchange(self, ex: Exchange) -> tuple[bytes, float]:
        """One request/reply; returns the reply line (with CR LF) and the send time."""
        try:
            if not self._in_step:
                self._resync(ex.frame)
            self._flush()
            sent_at = time.time()
            self._port.write(ex.frame)
            line = self._read_reply(ex.frame, ex.name)
        except _PORT_ERRORS as exc:
            raise ProbeDisconnected(
                f"serial port {self._name} failed during {ex.frame.strip()!r}: {exc}; the port has "
                "gone (USB adapter unplugged, unit switched off?) - reconnect and reopen it"
            ) from exc
        return line, sent_at

    def _flush(self) -> None:
        """Discard buffered input (counted when the port can tell how much there was)."""
        pending = getattr(self._port, "in_waiting", 0)
        pending = (pending if isinstance(pending, int) else 0) + len(self._rx)
        self._rx = b""
        if pending > 0:
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

    def _line_advice(self) -> str:
        d = self.dialect
        return (f"the station opens the line at {self.line.describe()}; a {d.title} offers {d.line.describe()}: "
                "set [devices] baudrate, probe_bytesize and probe_parity to the unit's own settings")

    def _lost_step(self, frame: bytes, line: bytes) -> ProbeTimeout | ProbeLineGarbled:
        """A wait ended without a complete reply: the line is out of step until a fence."""
        self._in_step = False
        self.stats.timeouts += 1
        log.warning("%s: no complete reply to %r within %s s (got %r); the line will be "
                    "resynchronised with %r before the next request", self._name, frame.strip(),
                    self._timeout, line[:40], self.dialect.resync.frame.strip())
        if line and _garbled(line):
            return ProbeLineGarbled(
                f"garbled reply to {frame.strip()!r} from {self._name} ({line[:24]!r}): the line settings "
                f"of station and unit differ or the line is noisy; {self._line_advice()}")
        if line:
            return ProbeTimeout(
                f"incomplete reply to {frame.strip()!r} from {self._name} within "
                f"{self._timeout} s ({line[:40]!r}): check the baud rate and the cable"
            )
        return ProbeTimeout(
            f"no reply to {frame.strip()!r} from {self._name} within {self._timeout} s: check "
            "that the unit is on, the cable (TX/RX crossed?), the baud rate, and that [devices] "
            f"probe_protocol ({self.dialect.name}) names the unit's dialect"
        )

    def _mismatch(self, line: bytes, sent: str, why: str) -> ProbeDialectMismatch:
        others = dialects_claiming(line, sent, besides=self.dialect.name)
        like = f"it answers like {' or '.join(repr(o) for o in others)}" if others else "its dialect is not known"
        return ProbeDialectMismatch(
            f"the probe unit at {self._name} does not speak {self.dialect.name!r}: it answered {sent!r} with "
            f"{line[:40]!r} ({why}); {like}. Set [devices] probe_protocol to the unit's dialect"
            + (f" (probe_protocol = {others[0]!r})" if others else ""))

    def _read_reply(self, frame: bytes, name: str) -> bytes:
        """Read lines until one names ``name``; discard the others (bounded)."""
        deadline = time.monotonic() + self._timeout
        sent = frame.rstrip(b"\r\n").decode("ascii", "replace")
        for _ in range(_MAX_DISCARDED_LINES):
            line = self._read_line()
            if not line.endswith(REPLY_TERMINATOR):
                raise self._lost_step(frame, line)
            if self.dialect.reply_names(line, name):
                return line
            if dialects_claiming(line, sent, besides=self.dialect.name):
                raise self._mismatch(line, sent, "another dialect's reply")
            self._discard(line, name)
            if time.monotonic() >= deadline:
                raise self._lost_step(frame, b"")
        raise self._lost_step(frame, b"")

    def _read_line(self) -> bytes:
        """One line as the port's ``read_until(REPLY_TERMINATOR, _MAX_REPLY_BYTES)`` gives it (the
        terminator included; what came before a timeout, without), but what the port already holds
        comes in one read: pyserial's read_until reads a byte at a time (98 000 reads, ~2 s of CPU
        in one simulated calibration). Bytes after the line wait in ``_rx`` for the next line, or
        :meth:`_flush` counts and discards them with the port's. A port without ``in_waiting`` and
        ``read`` (a scripted fake) is read with its own read_until."""
        if not hasattr(self._port, "read") or not isinstance(getattr(self._port, "in_waiting", None), int):
            return self._port.read_until(REPLY_TERMINATOR, _MAX_REPLY_BYTES)
        port = cast(_BufferedPort, self._port)  # pyserial's: SerialLike does not promise these
        buf, self._rx = self._rx, b""
        limit = getattr(port, "timeout", None)
        deadline = time.monotonic() + (self._timeout if limit is None else limit)
        while True:
            i = buf.find(REPLY_TERMINATOR, 0, _MAX_REPLY_BYTES)
            if i >= 0 or len(buf) >= _MAX_REPLY_BYTES:
                end = i + len(REPLY_TERMINATOR) if i >= 0 else _MAX_REPLY_BYTES
                buf, self._rx = buf[:end], buf[end:]
                return buf
            chunk = port.read(max(1, min(port.in_waiting, _MAX_REPLY_BYTES - len(buf))))
            buf += chunk
            if not chunk or time.monotonic() >= deadline:  # the port's timeout, as read_until's
                return buf

    def _resync(self, frame: bytes) -> None:
        """The fence: send the dialect's harmless read-only request and discard every line up to
        its answer. Raises ProbeTimeout (line still out of step) if it is not answered in time."""
        fence = self.dialect.resync
        self.stats.resyncs += 1
        self._flush()
        self._port.write(fence.frame)
        deadline = time.monotonic() + self._timeout
        last = b""
        for _ in range(_MAX_DISCARDED_LINES):
            line = self._read_line()
            last = line
            if not line.endswith(REPLY_TERMINATOR):
                break
            if self.dialect.reply_names(line, fence.name):
                self._in_step = True
                log.info("%s: line resynchronised (%r answered)", self._name, fence.frame.strip())
                return
            self._discard(line, f"{fence.name} (resynchronisation)")
            if time.monotonic() >= deadline:
                break
        self.stats.timeouts += 1
        if last and _garbled(last):
            raise ProbeLineGarbled(
                f"garbled answer ({last[:24]!r}) to the resynchronisation request {fence.frame.strip().decode('ascii')} from "
                f"{self._name}, so {frame.strip()!r} was not sent; {self._line_advice()}")
        raise ProbeTimeout(
            f"{self._name} did not answer the resynchronisation request {fence.frame.strip().decode('ascii')} within "
            f"{self._timeout} s after an earlier timeout, so {frame.strip()!r} was not sent: "
            "check that the unit is on, the cable and the baud rate"
        )

    def _run(self, ex: Exchange, retries: int | None = None):
        """Send an exchange and parse its reply, retrying read-only requests on transient faults
        (timeout, garbled frame, an error the dialect marks retryable; "retry after wait" ones
        wait first). Returns ``(parsed, raw, sent_at)``."""
        attempts = 1 + ((self._retries if retries is None else retries) if ex.read_only else 0)
        last: ProbeError | None = None
        for attempt in range(attempts):
            if attempt:
                self.stats.retries += 1
                log.warning("%s: repeating %r (attempt %d of %d) after: %s", self._name, ex.frame.strip(),
                            attempt + 1, attempts, last)
                if isinstance(last, ProbeDeviceError) and last.action is ErrorAction.RETRY_AFTER_WAIT:
                    time.sleep(self.dialect.retry_wait_s)
            try:
                raw, sent_at = self._exchange(ex)
                return ex.parse(raw), raw, sent_at
            except (ProbeTimeout, ProbeFrameError) as exc:
                last = exc
            except ProbeDeviceError as exc:
                if not exc.retryable:
                    raise
                last = exc
        assert last is not None
        if isinstance(last, ProbeDeviceError):
            raise last
        if ex.read_only:
            raise type(last)(f"{last} (gave up after {attempts} attempts)") from last
        raise type(last)(
            f"{last}; {ex.name} changes the unit's state and was not repeated - read the "
            "channel to see whether it took effect"
        ) from last

    def _transact(self, name: str, parse, *args):
        """A station-ascii command by name (the table says whether it may be repeated)."""
        from drivers.probe_protocol import COMMANDS

        return self._run(Exchange(format_request(name, *args), name, parse, COMMANDS[name].read_only))

    # ---------------------------------------------------------------- commands

    def identify(self) -> DeviceInfo:
        """The unit's identification. A dialect without an ID command (DL-RS1A, Mitutoyo) gets a
        DeviceInfo synthesised from what it answers: model, firmware "n/a", channel count."""
        d = self.dialect
        if d.identify is None:
            n = self._scan_channels() if d.needs_channel_scan else len(self._snapshot_once().status)
            self.info = d.info(n)
            self._channels = n
            return self.info
        ex = d.identify()
        try:
            info, raw, _ = self._run(ex)
        except ProbeDeviceError as exc:
            if exc.code == d.unknown_command_code:
                raise self._mismatch(f"ER,{ex.name},{exc.code:02d}".encode("ascii"), ex.name,
                                     f"{d.name} always knows {ex.name}") from exc
            raise
        self.info = info
        self._channels = info.channels
        return info

    def _scan_channels(self) -> int:
        """One request per channel: count the indicators that answer, from channel 0 up to the
        configured count (or until the first silent one). Channel 0 must answer."""
        limit = self._channels or 15
        n = 0
        for k in range(limit):
            try:  # past channel 0 a silent ID ends the scan: not worth a repetition
                self._run(self.dialect.snapshot(k + 1)[k], retries=None if k == 0 or self._channels else 0)
            except ProbeTimeout:
                if k == 0 or self._channels is not None:
                    raise
                break
            n += 1
        return n

    def _snapshot_once(self) -> ProbeSnapshot:
        if self._channels is None and self.dialect.needs_channel_scan:
            self._channels = self._scan_channels()
        fields: list = []
        raws: list[bytes] = []
        first: float | None = None
        for ex in self.dialect.snapshot(self._channels):
            parsed, raw, sent_at = self._run(ex)
            fields += parsed
            raws.append(raw)
            first = sent_at if first is None else first
        if self._channels is not None and len(fields) != self._channels:
            raise ProbeFrameError(
                f"{self.dialect.name} snapshot carries {len(fields)} channel(s), the unit had {self._channels}: "
                "garbled frame, or the unit was reconfigured; re-identify it")
        if self._channels is None:
            self._channels = len(fields)
        values = np.array([v for v, _ in fields], dtype=float)
        status = [s for _, s in fields]
        if self._valid is not None:
            lim = np.broadcast_to(self._valid, values.shape) if self._valid.size == 1 else self._valid[: values.size]
            for ch in range(min(values.size, lim.size)):
                if status[ch] is ChannelStatus.OK and abs(values[ch]) > lim[ch]:
                    status[ch] = ChannelStatus.OVER_RANGE if values[ch] > 0 else ChannelStatus.UNDER_RANGE
                    values[ch] = np.nan
        return ProbeSnapshot(_frozen(values), tuple(status), b"".join(raws), float(first or time.time()))

    def _fresh(self, tolerance_mm: float) -> ProbeSnapshot:
        """The freshness rule: two snapshots at least the dialect's refresh time apart that agree
        (same statuses, OK values within ``tolerance_mm``); at most ``settle_attempts`` pairs."""
        prev = self._snapshot_once()
        worst = (0, 0.0)
        for _ in range(self._settle_attempts):
            time.sleep(self.refresh_s)
            cur = self._snapshot_once()
            ok = np.array([a is ChannelStatus.OK and b is ChannelStatus.OK for a, b in zip(prev.status, cur.status)])
            diff = np.where(ok, np.abs(np.nan_to_num(cur.values_mm - prev.values_mm)), 0.0)
            if prev.status == cur.status and (diff.size == 0 or float(diff.max()) <= tolerance_mm):
                return ProbeSnapshot(cur.values_mm, cur.status, prev.raw + cur.raw, cur.timestamp)
            self.stats.unsettled += 1
            k = int(np.argmax(diff)) if diff.size else 0
            worst = max(worst, (k, float(diff[k]) if diff.size else 0.0), key=lambda w: w[1])
            prev = cur
        raise ProbeUnsettled(worst[0], worst[1], tolerance_mm, self._settle_attempts)

    def read_all(self) -> ProbeSnapshot:
        """Every channel; for a fresh-pair dialect, by the freshness rule."""
        if self.dialect.fresh_pair:
            return self._fresh(self._settle_tol)
        return self._snapshot_once()

    def read_channel(self, channel: int) -> tuple[float, ChannelStatus]:
        """One channel (0-based) -> ``(value_mm, status)``, NaN unless OK."""
        self._check_channel(channel)
        if self.dialect.name != "station-ascii":
            snap = self.read_all()
            return float(snap.values_mm[channel]), snap.status[channel]
        (value, status), _, _ = self._transact("MS", lambda line: parse_ms(line, channel), channel)
        return value, status

    def read_averaged(self, n: int, max_spread_mm: float) -> ProbeSnapshot:
        """Mean of ``n`` snapshots (a fresh-pair dialect: the first by the freshness rule with
        ``max_spread_mm`` as tolerance, the others each a refresh time later).

        A channel that is not OK in some snapshot is reported with the first such status and
        NaN. For OK channels the peak-to-peak spread must stay within ``max_spread_mm``, else
        :class:`ProbeSpreadError` (for the worst channel).
        """
        if n < 1:
            raise ValueError("n must be >= 1")
        if self.dialect.fresh_pair:
            snaps = [self._fresh(max_spread_mm)]
            for _ in range(n - 1):
                time.sleep(self.refresh_s)
                snaps.append(self._snapshot_once())
        else:
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

    def _station_only(self, what: str) -> None:
        if self.dialect.name != "station-ascii":
            raise ProbeConfigError(
                f"{what} is a station-ascii command; with {self.dialect.name} the station reads absolute values "
                "and sets no zero or preset (docs/protocols.md)")

    def zero(self, channel: int) -> None:
        """Make the channel's present reading 0.000 0 mm (station-ascii; never retried)."""
        self._station_only("zero (ZS)")
        self._check_channel(channel)
        self._transact("ZS", lambda line: parse_ack(line, "ZS", channel), channel)

    def preset(self, channel: int, value_mm: float) -> None:
        """Make the channel's present reading ``value_mm`` (station-ascii; never retried)."""
        self._station_only("preset (PS)")
        self._check_channel(channel)
        self._transact("PS", lambda line: parse_ack(line, "PS", channel), channel, value_mm)

    def clear_zero(self, channel: int) -> None:
        """Remove a zero or preset (station-ascii; never retried)."""
        self._station_only("zero clear (ZC)")
        self._check_channel(channel)
        self._transact("ZC", lambda line: parse_ack(line, "ZC", channel), channel)

    def _check_channel(self, channel: int) -> None:
        limit = self._channels
        if not isinstance(channel, (int, np.integer)) or channel < 0 or (
                limit is not None and channel >= limit):
            raise ValueError(
                f"channel {channel!r} outside 0..{(limit or 15) - 1} for {self._name}")
