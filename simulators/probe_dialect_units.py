"""Simulated probe interfaces of the real vendors, byte for byte as their documents describe them.

The frames are built and the requests read by :mod:`simulators.probe_wire`, the simulator's own
encoding written from the documents; from :mod:`drivers.probe_dialects` and
:mod:`drivers.probe_protocol` only the shared tables are imported (commands, error codes, data
numbers, limits), never the drivers' codecs, so that an encoding error of the driver cannot hide
behind the same error in the simulator.

* :class:`StationUnit`: the station's own dialect (zero/preset offsets, ``ID``).
* :class:`KeyenceUnit`: a DL-RS1A with ``n`` GT2 amplifiers (IDs 00 ..). It answers only its
  manual's commands (``M0``, ``MS``, ``SR``, ``SW``, ``AW``; anything else, ``ID`` included, is
  ``ER,<cmd>,00``); ``M0`` / ``MS`` return a buffer refreshed every ``refresh_s``, as the unit
  polls its amplifiers; ``SW`` / ``AW`` are refused with 67 unless ``writable`` (the unit's
  read/write switch).
* :class:`MitutoyoUnit`: ``n`` Digimatic indicators with IDs 01 .. n on one line (``GA**`` ->
  ``G<mode>**,±DDDD.DDDD``; mode and zero/preset commands -> ``CH**``); a request for an ID no
  indicator has, or a command the manual lacks, gets no answer [?].

Both take ``source()`` -> channel values [mm] (+inf over, -inf under range, NaN invalid) and the
server's :class:`~simulators.probe_head_sim.ProbeFaults`; ``handle(line)`` returns the reply
bytes (None: silence) and ``busy_reply(line)`` what a busy unit answers (None: silence).
"""

from __future__ import annotations

import math
import threading
import time
from typing import Callable

import numpy as np

from drivers.probe_dialects.keyence_dl_rs1a import DATA_NUMBERS as KEYENCE_DATA_NUMBERS
from drivers.probe_dialects.keyence_dl_rs1a import MAX_AMPLIFIERS as KEYENCE_MAX_AMPLIFIERS
from drivers.probe_dialects.mitutoyo_ga import MAX_CHANNELS as MITUTOYO_MAX_CHANNELS
from drivers.probe_dialects.mitutoyo_ga import VALUE_LIMIT_MM as MITUTOYO_VALUE_LIMIT_MM
from drivers.probe_protocol import (
    ERR_BUSY,
    ERR_NO_CHANNEL,
    ERR_NOT_MEASURING,
    ERR_OUT_OF_RANGE,
    VALUE_LIMIT_MM,
    ChannelStatus,
)
from simulators import probe_wire as wire
from simulators.probe_wire import Refusal

__all__ = ["StationUnit", "KeyenceUnit", "MitutoyoUnit"]

_STATUS_VALUE = {ChannelStatus.OVER_RANGE: math.inf, ChannelStatus.UNDER_RANGE: -math.inf,
                 ChannelStatus.INVALID: math.nan}


class StationUnit:
    """station-ascii (:mod:`drivers.probe_protocol`): the unit's state offsets (zero/preset) and request handling. No I/O."""

    def __init__(self, source: Callable[[], np.ndarray], n_channels: int, model: str,
                 firmware: str, faults) -> None:
        self.source = source
        self.n = n_channels
        self.model = model
        self.firmware = firmware
        self.faults = faults
        self.offsets = np.zeros(n_channels)
        self.requests = 0

    def _raw(self) -> np.ndarray:
        values = np.asarray(self.source(), dtype=float)
        if values.shape != (self.n,):
            raise ValueError(f"snapshot_source returned shape {values.shape}, expected ({self.n},)")
        for ch, status in self.faults._forced_now().items():
            if ch < self.n:
                values = values.copy()
                values[ch] = _STATUS_VALUE[status]
        return values

    def _displayed(self) -> np.ndarray:
        return self._raw() - self.offsets  # inf/NaN stay markers

    def busy_reply(self, line: bytes) -> bytes | None:
        return wire.station_error(wire.busy_echo(line), ERR_BUSY)

    def handle(self, line: bytes) -> bytes:
        """Reply (CR LF terminated) to one request line without its terminator."""
        self.requests += 1
        try:
            name, args = wire.station_request(line)
            return self._execute(name, args)
        except Refusal as exc:
            return wire.station_error(exc.command, exc.code)

    def _check(self, name: str, ch: int) -> None:
        if ch >= self.n:
            raise Refusal(name, ERR_NO_CHANNEL)

    def _execute(self, name: str, args: tuple) -> bytes:
        if name == "M0":
            return wire.station_m0(self._displayed())
        if name == "MS":
            self._check(name, args[0])
            return wire.station_ms(args[0], self._displayed()[args[0]])
        if name == "ID":
            return wire.station_id(self.model, self.firmware, self.n)
        ch = args[0]
        self._check(name, ch)
        if name == "ZC":
            self.offsets[ch] = 0.0
            return wire.station_ack("ZC", ch)
        raw = self._raw()[ch]
        if not math.isfinite(raw):
            raise Refusal(name, ERR_NOT_MEASURING)
        if name == "ZS":
            self.offsets[ch] = raw
            return wire.station_ack("ZS", ch)
        # PS: the present reading becomes the preset value
        if abs(args[1]) > VALUE_LIMIT_MM:
            raise Refusal(name, ERR_OUT_OF_RANGE)
        self.offsets[ch] = raw - args[1]
        return wire.station_ps(ch, args[1])


class _Source:
    def __init__(self, source: Callable[[], np.ndarray], n: int, faults) -> None:
        self.source = source
        self.n = n
        self.faults = faults
        self.requests = 0

    def values(self) -> np.ndarray:
        values = np.array(self.source(), dtype=float)
        if values.shape != (self.n,):
            raise ValueError(f"snapshot_source returned shape {values.shape}, expected ({self.n},)")
        for ch, status in self.faults._forced_now().items():
            if ch < self.n:
                values[ch] = _STATUS_VALUE[status]
        return values


class KeyenceUnit(_Source):
    """DL-RS1A + GT2 amplifiers (:mod:`drivers.probe_dialects.keyence_dl_rs1a`)."""

    def __init__(self, source: Callable[[], np.ndarray], n_channels: int, faults, refresh_s: float = 0.02,
                 writable: bool = False) -> None:
        if not 1 <= n_channels <= KEYENCE_MAX_AMPLIFIERS:
            raise ValueError(f"a DL-RS1A serves 1 .. {KEYENCE_MAX_AMPLIFIERS} amplifiers, not {n_channels}")
        super().__init__(source, n_channels, faults)
        self.refresh_s = refresh_s
        self.writable = writable
        self.data = [{no: v for no, (_, v) in KEYENCE_DATA_NUMBERS.items()} for _ in range(n_channels)]
        self._buffer: np.ndarray | None = None
        self._buffered_at = -math.inf
        self._lock = threading.Lock()

    def _buffered(self) -> np.ndarray:
        """The unit polls its amplifiers periodically; M0/MS between two polls see one buffer."""
        now = time.monotonic()
        with self._lock:
            if self._buffer is None or now - self._buffered_at >= self.refresh_s:
                self._buffer = self.values()
                self._buffered_at = now
            return self._buffer.copy()

    def busy_reply(self, line: bytes) -> bytes | None:
        """Amplifiers starting up: ``ER,<cmd>,22`` (the manual: "resend the command")."""
        return wire.keyence_error(wire.busy_echo(line), wire.KEYENCE_PARAMETER)

    def handle(self, line: bytes) -> bytes | None:
        self.requests += 1
        try:
            name, params = wire.keyence_request(line)
            return self._execute(name, params)
        except Refusal as exc:
            return wire.keyence_error(exc.command, exc.code)

    def _amp(self, name: str, field: bytes) -> int:
        amp = int(field)
        if amp >= self.n:
            raise Refusal(name, wire.KEYENCE_ID_NUMBER)
        return amp

    def _number(self, name: str, field: bytes) -> int:
        no = int(field)
        if no not in KEYENCE_DATA_NUMBERS:  # this simulator serves only the documented GT2 items
            raise Refusal(name, wire.KEYENCE_PARAMETER)
        return no

    def _execute(self, name: str, params: tuple[bytes, ...]) -> bytes:
        if name == "M0":
            return wire.keyence_m0(self._buffered())
        if name == "MS":
            # [?] GT2 control-output digits; "0" (all outputs off) as no judgment limits are set
            return wire.keyence_ms(self._buffered(), output=0)
        if name == "SR":
            amp, no = self._amp(name, params[0]), self._number(name, params[1])
            return wire.keyence_sr(amp, no, self.data[amp][no])
        if not self.writable:
            raise Refusal(name, wire.KEYENCE_WRITE_CONTROL)
        if name == "SW":
            amp, no = self._amp(name, params[0]), self._number(name, params[1])
            self.data[amp][no] = params[2]
            return wire.keyence_sw(amp, no)
        no = self._number(name, params[0])  # AW
        for item in self.data:
            item[no] = params[1]
        return wire.keyence_aw(no)


class MitutoyoUnit(_Source):
    """Digimatic indicators with IDs 01 .. n (:mod:`drivers.probe_dialects.mitutoyo_ga`)."""

    def __init__(self, source: Callable[[], np.ndarray], n_channels: int, faults) -> None:
        if not 1 <= n_channels <= MITUTOYO_MAX_CHANNELS:
            raise ValueError(f"the Mitutoyo dialect serves 1 .. {MITUTOYO_MAX_CHANNELS} indicators, not {n_channels}")
        super().__init__(source, n_channels, faults)
        self.modes = [b"N"] * n_channels
        self.offsets = np.zeros(n_channels)

    def busy_reply(self, line: bytes) -> bytes | None:
        return None  # no busy reply is documented [?]: a busy indicator is a silent one

    def handle(self, line: bytes) -> bytes | None:
        self.requests += 1
        request = wire.mitutoyo_request(line)
        if request is None or not 1 <= request[1] <= self.n:
            return None
        cmd, ident, rest = request
        k = ident - 1
        if cmd == "GA" and not rest:
            v = self.values()[k]
            # [?] over range / no reading have no documented form: the largest value, which the
            # driver decodes as not a measurement
            limit = MITUTOYO_VALUE_LIMIT_MM
            shown = v - self.offsets[k] if math.isfinite(v) else (-limit if v < 0 else limit)
            shown = float(np.clip(shown, -limit, limit))
            return wire.mitutoyo_data(self.modes[k], ident, shown)
        if cmd in ("CN", "CX", "CM", "CW") and not rest:
            self.modes[k] = cmd[1:].encode("ascii")
        elif cmd == "CR" and not rest:
            v = self.values()[k]
            self.offsets[k] = v if math.isfinite(v) else self.offsets[k]
        elif cmd == "CP" and rest[:1] == b",":
            preset = wire.mitutoyo_parse_value(rest[1:])
            if preset is None:
                return None
            v = self.values()[k]
            self.offsets[k] = v - preset if math.isfinite(v) else self.offsets[k]
        else:
            return None
        return wire.mitutoyo_ack(ident)
