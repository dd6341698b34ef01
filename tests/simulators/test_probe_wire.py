"""The simulator's own probe wire encoding (simulators/probe_wire.py) against the documents'
examples, and against the drivers' independent codecs in both directions.

Two implementations of each dialect's encoding exist on purpose: the driver's
(drivers/probe_protocol.py, drivers/probe_dialects/*) and the simulated unit's. Byte-exact checks
against the documents catch an error both share; the cross-checks catch one either makes alone.
"""

from __future__ import annotations

import ast
import importlib
import inspect
import math
from decimal import ROUND_HALF_EVEN, Decimal, localcontext
from pathlib import Path

import numpy as np
import pytest

from drivers import probe_protocol as pp
from drivers.probe_dialects import keyence_dl_rs1a as kd
from drivers.probe_dialects import mitutoyo_ga as md
from drivers.probe_protocol import ChannelStatus, ProbeDeviceError, ProbeFrameError
from simulators import probe_dialect_units, probe_wire
from simulators import probe_wire as wire
from simulators.probe_dialect_units import KeyenceUnit, MitutoyoUnit, StationUnit
from simulators.probe_head_sim import ProbeFaults
from simulators.probe_wire import Refusal

ROOT = Path(__file__).resolve().parents[2]
SEED = 20261202
INF, NAN = math.inf, math.nan
#: the largest rounding error of a 0.0001 mm field, plus the float error of the subtraction
HALF_UNIT = 0.00005 + 1e-9

#: the rounding edges and limits of all three dialects
EDGES = [0.0, -0.0, 0.00005, -0.00005, 0.000049999, -0.000049999, 0.00015, -0.00015, 0.00025, 1.23445, -1.23455,
         199.9999, -199.9999, 199.99994, -199.99994, 199.99995, -199.99995, 200.0, -200.0,
         999.9999, -999.9999, 999.99994, 999.99995, -999.99995, 1000.0, -1000.0,
         9999.9999, -9999.9999, 9999.99995, -9999.99995, 10000.0, 1e-12, -1e-12, 1e12, -1e300,
         # exact binary halves of the last place (625 * (2k + 1) / 20000): half to even decides
         0.03125, -0.03125, 0.09375, 1.03125, -199.96875, 999.96875,
         INF, -INF, NAN]


def value_corpus() -> np.ndarray:
    """The edges, random readings of several magnitudes, and values on and next to the half-unit
    rounding boundaries (k + 1/2) * 0.0001 mm."""
    rng = np.random.default_rng(SEED)
    halves = (rng.integers(-99_999_999, 99_999_999, 3000) + 0.5) / 10_000
    near = np.concatenate([np.nextafter(halves, INF), np.nextafter(halves, -INF)])
    return np.concatenate([
        np.array(EDGES), rng.uniform(-2.0, 2.0, 3000), rng.uniform(-250.0, 250.0, 3000),
        rng.uniform(-1100.0, 1100.0, 3000), rng.uniform(-11_000.0, 11_000.0, 3000),
        np.round(rng.uniform(-300.0, 300.0, 3000), 4), halves, near,
    ])


VALUES = value_corpus()


def oracle_field(v: float, int_digits: int, limit: str, specials: dict[ChannelStatus, bytes]) -> bytes:
    """A third implementation of the fixed-point field: exact decimal arithmetic on the binary
    value, rounded half to even to 0.0001 mm; the documented width; the dialect's specials."""
    if math.isnan(v):
        return specials[ChannelStatus.INVALID]
    if math.isinf(v):
        return specials[ChannelStatus.OVER_RANGE if v > 0 else ChannelStatus.UNDER_RANGE]
    with localcontext() as ctx:
        ctx.prec = 1000
        q = Decimal(v).quantize(Decimal("0.0001"), rounding=ROUND_HALF_EVEN)
    if abs(q) > Decimal(limit):
        return specials[ChannelStatus.OVER_RANGE if q > 0 else ChannelStatus.UNDER_RANGE]
    return ("-" if q < 0 else "+").encode() + format(abs(q), f"0{int_digits + 5}.4f").encode()


def same_float(a: float, b: float) -> bool:
    """Bit for bit (NaN equals NaN, -0.0 differs from +0.0)."""
    return (math.isnan(a) and math.isnan(b)) or a.hex() == b.hex()


# --------------------------------------------------------------------------------------------
# (a) exact bytes: the documents' examples
# --------------------------------------------------------------------------------------------


def station(values, **kw) -> StationUnit:
    arr = np.asarray(values, dtype=float)
    return StationUnit(lambda: arr, len(arr), kw.get("model", "SIM-PH6"), kw.get("firmware", "1.0.0"), ProbeFaults())


def test_station_ascii_value_fields_per_field_formats_and_markers():
    """docs/protocols.md, station-ascii "Field formats" and "Markers"."""
    assert wire.station_value(12.3456) == b"+012.3456"
    assert wire.station_value(-0.0021) == b"-000.0021"
    assert wire.station_value(0.0) == wire.station_value(-0.0) == wire.station_value(-0.00004) == b"+000.0000"
    assert wire.station_value(999.9999) == b"+999.9999" and wire.station_value(-999.9999) == b"-999.9999"
    assert wire.station_value(999.99995) == b"+FFFFFFF" and wire.station_value(-1000.0) == b"-FFFFFFF"
    assert wire.station_value(INF) == b"+FFFFFFF" and wire.station_value(-INF) == b"-FFFFFFF"
    assert wire.station_value(NAN) == b"XXXXXXXX"
    assert {len(wire.station_value(v)) for v in VALUES if abs(v) <= 999.9999} == {9}
    assert {len(wire.station_value(v)) for v in (INF, -INF, NAN, 5e3, -5e3)} == {8}
    assert wire.station_parse_value(b"+012.3456") == 12.3456
    for bad in (b"+12.3456", b"012.3456", b"+012.345", b"+012,3456", b"+FFFFFFF", b"+0\xd9\xa12.3456", b""):
        assert wire.station_parse_value(bad) is None


def test_station_ascii_transcript_of_the_documents_examples():
    """docs/protocols.md, station-ascii "Examples", byte for byte through the simulated unit."""
    unit = station([0.1234, -0.0021, 1.5, INF, NAN, -0.5])
    assert unit.handle(b"ID") == b"ID,SIM-PH6,1.0.0,06\r\n"
    assert unit.handle(b"M0") == b"M0,+000.1234,-000.0021,+001.5000,+FFFFFFF,XXXXXXXX,-000.5000\r\n"
    assert unit.handle(b"MS,02\r\n") == b"MS,02,+001.5000\r\n"
    assert unit.handle(b"ZS,02") == b"ZS,02\r\n"
    assert unit.handle(b"MS,02") == b"MS,02,+000.0000\r\n"
    assert unit.handle(b"PS,05,+002.0000") == b"PS,05,+002.0000\r\n"
    assert unit.handle(b"MS,05") == b"MS,05,+002.0000\r\n"
    assert unit.handle(b"ZC,02") == b"ZC,02\r\n"
    assert unit.handle(b"MS,02") == b"MS,02,+001.5000\r\n"
    assert unit.handle(b"ZS,04") == b"ER,ZS,04\r\n"
    assert unit.handle(b"MS,09") == b"ER,MS,03\r\n"
    assert unit.handle(b"M1") == b"ER,M1,00\r\n"
    assert unit.handle(b"MS,3") == b"ER,MS,01\r\n"
    assert unit.handle(b"PS,01,+FFFFFFF") == b"ER,PS,02\r\n"
    assert unit.handle(b"MS," + b"0" * 70) == b"ER,MS,01\r\n"  # "longer than 64 bytes is refused"
    assert unit.handle(b"m0," + b"0" * 70) == b"ER,??,01\r\n"
    assert unit.busy_reply(b"M0") == b"ER,M0,05\r\n"


def test_station_ascii_frame_lengths_match_the_timing_table():
    """docs/protocols.md, station-ascii "Timing": M0 of 6 numbers 64 bytes, of 15 154; MS 17."""
    assert len(wire.station_m0([1.0] * 6)) == 64
    assert len(wire.station_m0([-1.0] * 15)) == 154
    assert len(wire.station_ms(3, 0.5)) == 17
    assert len(wire.station_m0([1.0, INF])) == len(wire.station_m0([1.0, 2.0])) - 1  # a marker is one shorter


def test_station_ascii_requests_decode_per_frames_and_error_codes():
    assert wire.station_request(b"M0\r") == ("M0", ())
    assert wire.station_request(b"MS,02\r\n") == ("MS", (2,))
    assert wire.station_request(b"PS,05,-002.5000") == ("PS", (5, -2.5))
    for line, echo, code in [(b"M1", "M1", 0), (b"MS,3", "MS", 1), (b"MS", "MS", 1), (b"ID,01", "ID", 1),
                             (b"PS,01,XXXXXXXX", "PS", 2), (b"PS,01,+1.5", "PS", 1), (b"m0", "??", 0),
                             (b"", "??", 0), (b"MS,\xd9\xa1\xd9\xa2", "MS", 1)]:
        with pytest.raises(Refusal) as err:
            wire.station_request(line)
        assert (err.value.command, err.value.code) == (echo, code), line
    with pytest.raises(ValueError):
        wire.station_id("no spaces allowed", "1.0", 6)
    with pytest.raises(ValueError):
        wire.station_ms(15, 0.0)
    with pytest.raises(ValueError):
        wire.station_m0([0.0] * 16)


def keyence(values, **kw) -> KeyenceUnit:
    arr = np.asarray(values, dtype=float)
    return KeyenceUnit(lambda: arr, len(arr), ProbeFaults(), refresh_s=0.0, **kw)


def test_keyence_frames_of_the_manual():
    """DL-RS1A manual (GT2): p. 8 example SR,06,101 and error response, p. 9 M0/MS, pp. 11-13
    the 9-byte ±DDD.DDDD value, p. 14 error numbers; docs/protocols.md "Example (at 9600 8N1)"."""
    assert wire.keyence_request(b"SR,06,101\r\n") == ("SR", (b"06", b"101"))
    assert wire.keyence_request(b"SR,06,101\r") == ("SR", (b"06", b"101"))  # p. 7: CR or CR LF
    assert wire.keyence_error("SR", 65) == b"ER,SR,65\r\n"
    assert wire.keyence_sr(1, 134, b"1") == b"SR,01,134,1\r\n"
    assert wire.keyence_sw(2, 103) == b"SW,02,103\r\n" and wire.keyence_aw(103) == b"AW,103\r\n"
    assert wire.keyence_value(-0.0021) == b"-000.0021" and wire.keyence_value(199.9999) == b"+199.9999"
    assert {len(wire.keyence_value(v)) for v in VALUES} == {9}
    assert wire.keyence_value(199.99995) == b"+999.9999" and wire.keyence_value(-INF) == b"-999.9999"
    assert wire.keyence_value(NAN) == b"+EEE.EEEE"
    unit = keyence([0.1234, -0.0021, 1.5, INF, NAN, -0.5])
    assert unit.handle(b"M0\r\n") == b"M0,+000.1234,-000.0021,+001.5000,+999.9999,+EEE.EEEE,-000.5000\r\n"
    assert unit.handle(b"MS") == b"MS,0,+000.1234,0,-000.0021,0,+001.5000,0,+999.9999,0,+EEE.EEEE,0,-000.5000\r\n"
    assert unit.handle(b"ID\r\n") == b"ER,ID,00\r\n"
    assert unit.handle(b"SR,06,101\r\n") == b"ER,SR,65\r\n"  # no amplifier 06
    assert unit.handle(b"SR,05,103") == b"SR,05,103,3\r\n"
    assert unit.handle(b"SW,05,103,2") == b"ER,SW,67\r\n"  # read/write switch on R
    assert unit.handle(b"SR,05") == b"ER,SR,21\r\n" and unit.handle(b"SR,5,103") == b"ER,SR,22\r\n"
    assert unit.busy_reply(b"M0") == b"ER,M0,22\r\n"
    assert len(wire.keyence_m0([1.0] * 6)) == 64  # docs: "4 + 64 bytes"
    for code in (wire.KEYENCE_INVALID_COMMAND, wire.KEYENCE_PARAMETER_COUNT, wire.KEYENCE_PARAMETER,
                 wire.KEYENCE_ID_NUMBER, wire.KEYENCE_WRITE_CONTROL):
        assert code in kd.ERRORS


def test_mitutoyo_frames_of_section_4_2_4():
    """ID-H0530/0560 manual No. 99MAH016B, 4.2.4: GA** -> GN**,+0016.2345; CP**,+0016.2345 -> CH**."""
    assert wire.mitutoyo_data(b"N", 1, 16.2345) == b"GN01,+0016.2345\r\n"
    assert wire.mitutoyo_data(b"M", 1, -16.2345) == b"GM01,-0016.2345\r\n"
    assert wire.mitutoyo_ack(12) == b"CH12\r\n"
    assert wire.mitutoyo_request(b"GA01\r\n") == ("GA", 1, b"")
    assert wire.mitutoyo_request(b"CP03,+0016.2345\r\n") == ("CP", 3, b",+0016.2345")
    assert wire.mitutoyo_parse_value(b"+0016.2345") == 16.2345
    assert wire.mitutoyo_value(-0.00004) == b"+0000.0000"
    assert {len(wire.mitutoyo_value(v)) for v in VALUES if abs(v) <= 9999.9999} == {10}
    for line in (b"GA1", b"GA", b"XX01", b"ga01", b"G\xc1\xc101"):
        assert wire.mitutoyo_request(line) is None, line  # two-digit ID No. of the table's commands only
    for v in (NAN, INF, -INF, 10_000.0, -9999.99996):
        with pytest.raises(ValueError):
            wire.mitutoyo_value(v)
    unit = MitutoyoUnit(lambda: np.array([16.2345, NAN]), 2, ProbeFaults())
    assert unit.handle(b"GA01\r\n") == b"GN01,+0016.2345\r\n"
    assert unit.handle(b"GA02\r\n") == b"GN02,+9999.9999\r\n"  # [?] no reading: the largest value
    assert unit.handle(b"CP01,+0001.0000") == b"CH01\r\n" and unit.handle(b"GA01") == b"GN01,+0001.0000\r\n"
    assert unit.handle(b"CP01,+9999.9999") == b"CH01\r\n" and unit.handle(b"GA01") == b"GN01,+9999.9999\r\n"
    assert unit.handle(b"CX01") == b"CH01\r\n" and unit.handle(b"GA01") == b"GX01,+9999.9999\r\n"
    assert unit.handle(b"GA03") is None and unit.handle(b"GA1") is None


# --------------------------------------------------------------------------------------------
# (b) cross-checks: the simulator's encoding against the driver's, both directions
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("dialect", ["station-ascii", "keyence-dl-rs1a"])
def test_value_fields_agree_with_the_drivers_codec_both_ways(dialect):
    # both dialects' number is the same ±DDD.DDDD field: the unit's one decoder reads either
    sim_format, sim_parse, drv_format, drv_parse, limit, specials = {
        "station-ascii": (wire.station_value, wire.station_parse_value, pp.format_value, pp.parse_value,
                          pp.VALUE_LIMIT_MM, pp.MARKERS),
        "keyence-dl-rs1a": (wire.keyence_value, wire.station_parse_value, kd.format_value, kd.parse_value,
                            kd.VALUE_LIMIT_MM, kd.SPECIAL_VALUES),
    }[dialect]
    seen = set()
    for v in VALUES.tolist():
        field = sim_format(v)
        assert field == oracle_field(v, 3, f"{limit:.4f}", specials), v
        assert field == drv_format(v), v
        decoded, status = drv_parse(field)
        seen.add(status)
        if math.isnan(v):
            assert status is ChannelStatus.INVALID
        elif status is ChannelStatus.OK:
            assert abs(decoded - v) <= HALF_UNIT and abs(decoded) <= limit, v
            back = sim_parse(field)
            assert back is not None and same_float(back, decoded), field  # the unit's decoder agrees bit for bit
        else:
            assert math.isnan(decoded)
            assert status is (ChannelStatus.OVER_RANGE if v > 0 else ChannelStatus.UNDER_RANGE), v
            assert abs(v) > limit
    assert seen == set(ChannelStatus)


def test_mitutoyo_values_agree_with_the_drivers_codec_both_ways():
    checked = 0
    for v in VALUES.tolist():
        try:
            expected = md.format_value(v)
        except ValueError:
            with pytest.raises(ValueError):
                wire.mitutoyo_value(v)
            continue
        field = wire.mitutoyo_value(v)
        assert field == expected == oracle_field(v, 4, "9999.9999", {}), v
        decoded, status = md.parse_value(field)
        preset = wire.mitutoyo_parse_value(field)
        assert preset is not None and abs(preset - v) <= HALF_UNIT
        if status is ChannelStatus.OK:
            assert same_float(preset, decoded), field
        checked += 1
    assert checked > len(VALUES) // 2


def fuzz_lines(alphabet: bytes, words: list[bytes], n: int = 4000) -> list[bytes]:
    rng = np.random.default_rng(SEED)
    lines = []
    for _ in range(n):
        if rng.random() < 0.5:
            size = int(rng.integers(0, 72))
            lines.append(bytes(alphabet[i] for i in rng.integers(0, len(alphabet), size)))
        else:
            parts = [words[i] for i in rng.integers(0, len(words), int(rng.integers(1, 5)))]
            lines.append(b",".join(parts) + [b"", b"\r", b"\r\n"][int(rng.integers(0, 3))])
    return lines


def outcome(parse, line):
    try:
        return "ok", parse(line)
    except (Refusal, ProbeDeviceError) as exc:
        return "refused", exc.command, exc.code


def test_station_request_parsers_agree_on_any_line():
    words = [b"M0", b"MS", b"ID", b"ZS", b"PS", b"ZC", b"M1", b"??", b"00", b"14", b"3", b"+012.3456", b"-999.9999",
             b"+FFFFFFF", b"XXXXXXXX", b"+1.5", b"", b"0" * 60]
    refused = 0
    for line in fuzz_lines(b"MSIDZPCR0123456789,.+-FX?\r\n m\xff", words):
        sim, drv = outcome(wire.station_request, line), outcome(pp.parse_request, line)
        if drv[0] == "ok":
            assert sim[0] == "ok" and sim[1][0] == drv[1].name, line
            assert all(type(a) is type(b) and (a == b if isinstance(a, int) else same_float(a, b))
                       for a, b in zip(sim[1][1], drv[1].args, strict=True)), line
        else:
            assert sim == drv, line
            refused += 1
    assert 0 < refused < 4000


def test_station_driver_requests_decode_in_the_simulator():
    rng = np.random.default_rng(SEED)
    for ch, v in zip(rng.integers(0, pp.MAX_CHANNELS, 2000).tolist(), rng.uniform(-999.9999, 999.9999, 2000).tolist()):
        assert wire.station_request(pp.format_request("MS", ch)) == ("MS", (ch,))
        name, (got_ch, got_v) = wire.station_request(pp.format_request("PS", ch, v))
        assert (name, got_ch) == ("PS", ch) and same_float(got_v, pp.parse_value(pp.format_value(v))[0])
    for name in ("M0", "ID"):
        assert wire.station_request(pp.format_request(name)) == (name, ())


def test_station_replies_decode_in_the_driver():
    rng = np.random.default_rng(SEED)
    for _ in range(300):
        n = int(rng.integers(1, pp.MAX_CHANNELS + 1))
        values = rng.choice(VALUES, n)
        frame = wire.station_m0(values)
        assert frame == pp.format_reply("M0", *values)
        decoded, statuses = pp.parse_m0(frame, n)
        for v, d, s in zip(values.tolist(), decoded.tolist(), statuses):
            assert (s is ChannelStatus.OK) == (oracle_field(v, 3, "999.9999", pp.MARKERS) not in pp.MARKERS.values())
            assert s is not ChannelStatus.OK or abs(d - v) <= HALF_UNIT
        ch = int(rng.integers(0, n))
        assert same_float(pp.parse_ms(wire.station_ms(ch, values[ch]), ch)[0], pp.parse_value(wire.station_value(values[ch]))[0])
    assert pp.parse_id(wire.station_id("SIM-PH6", "1.0.0", 6)) == pp.DeviceInfo("SIM-PH6", "1.0.0", 6)
    assert pp.parse_ack(wire.station_ack("ZS", 4), "ZS", 4) == (4,)
    assert pp.parse_ack(wire.station_ack("ZC", 14), "ZC", 14) == (14,)
    assert pp.parse_ack(wire.station_ps(5, 2.0), "PS", 5) == (5, (2.0, ChannelStatus.OK))
    for code in pp.ERROR_CODES:
        with pytest.raises(ProbeDeviceError) as err:
            pp.parse_reply(wire.station_error("MS", code), "MS")
        assert err.value.code == code


def test_keyence_request_parsers_agree_on_any_line():
    words = [b"M0", b"MS", b"SR", b"SW", b"AW", b"ID", b"M0X", b"06", b"6", b"101", b"1011", b"+12.5", b"-0003",
             b"12345678901", b"A", b""]
    refused = 0
    for line in fuzz_lines(b"MSRWAID0123456789,.+-?E\r\n s\x80", words):
        sim, drv = outcome(wire.keyence_request, line), outcome(kd.parse_request, line)
        assert sim == drv, line
        refused += sim[0] == "refused"
    assert 0 < refused < 4000
    for amp, no in [(0, 103), (14, 121), (6, 101)]:
        assert wire.keyence_request(kd.request("SR", b"%02d" % amp, b"%03d" % no)) == ("SR", (b"%02d" % amp, b"%03d" % no))
    assert wire.keyence_request(kd.request("M0")) == ("M0", ())


def test_keyence_replies_decode_in_the_driver():
    rng = np.random.default_rng(SEED)
    for _ in range(300):
        n = int(rng.integers(1, kd.MAX_AMPLIFIERS + 1))
        values = rng.choice(VALUES, n)
        m0, ms = kd.parse_m0(wire.keyence_m0(values)), kd.parse_ms(wire.keyence_ms(values))
        assert [s for _, s in m0] == [s for _, _, s in ms] and len(m0) == n
        for v, (d, s), (out, d2, _) in zip(values.tolist(), m0, ms):
            assert out == 0 and same_float(d, d2)
            assert (s is ChannelStatus.OK) == (oracle_field(v, 3, "199.9999", kd.SPECIAL_VALUES)
                                               not in kd.SPECIAL_VALUES.values()), v
            assert s is not ChannelStatus.OK or abs(d - v) <= HALF_UNIT
    assert kd.parse_sr(wire.keyence_sr(6, 101, b"3"), 6, 101) == b"3"
    for code in kd.ERRORS:
        with pytest.raises(ProbeDeviceError) as err:
            kd.parse_m0(wire.keyence_error("M0", code))
        assert err.value.code == code


def test_mitutoyo_requests_and_replies_cross_the_driver():
    rng = np.random.default_rng(SEED)
    for ident, v in zip(rng.integers(1, 100, 500).tolist(), rng.uniform(-9999.9999, 9999.9999, 500).tolist()):
        assert wire.mitutoyo_request(md.request("GA", ident)) == ("GA", ident, b"")
        request = wire.mitutoyo_request(md.request("CP", ident, md.format_value(v)))
        assert request is not None
        cmd, got, rest = request
        assert (cmd, got) == ("CP", ident) and wire.mitutoyo_parse_value(rest[1:]) is not None
        [(d, s)] = md.parse_ga(wire.mitutoyo_data(b"N", ident, v), ident)
        assert s is ChannelStatus.OK and abs(d - v) <= HALF_UNIT
        assert md.reply_names(wire.mitutoyo_data(b"W", ident, v), f"G?{ident:02d}")
    with pytest.raises(ProbeDeviceError):
        md.parse_ga(wire.mitutoyo_data(b"X", 3, 1.0), 3)  # not normal mode
    with pytest.raises(ProbeFrameError):
        md.parse_ga(wire.mitutoyo_data(b"N", 3, 1.0), 4)  # another indicator's reply
    [(d, s)] = md.parse_ga(wire.mitutoyo_data(b"N", 2, 9999.9999), 2)
    assert s is ChannelStatus.OVER_RANGE and math.isnan(d)  # the simulator's "no reading" [?]


# --------------------------------------------------------------------------------------------
# independence: the simulator's probe side imports the drivers' tables, never their codecs
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("module", [probe_wire, probe_dialect_units], ids=lambda m: m.__name__)
def test_simulated_units_import_only_tables_from_the_drivers(module):
    tree = ast.parse(Path(inspect.getfile(module)).read_text())
    imported = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            assert not any(a.name.startswith("drivers") for a in node.names), ast.dump(node)
        elif isinstance(node, ast.ImportFrom) and node.module is not None and node.module.startswith("drivers"):
            for alias in node.names:
                where = f"{node.module}.{alias.name}"
                obj = getattr(importlib.import_module(node.module), alias.name)
                imported.append(where)
                assert not callable(obj) or inspect.isclass(obj), f"{where} is code, not a table"
                assert not inspect.ismodule(obj), f"{where}: a whole module brings its codecs"
    assert imported
