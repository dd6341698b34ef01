"""Register map: encoding, word orders, decoders that fail only with the driver's errors."""

import contextlib

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from drivers.controller_map import (
    REG,
    REGISTERS,
    TABLE_HEADER_REGISTERS,
    WINDOW_SIZE,
    ControllerError,
    RegisterDecodeError,
    WordOrder,
    decode,
    decode_i32_array,
    encode,
    encode_i32_array,
    register_span,
)
from drivers.controller_status import ControllerStatus
from drivers.correction_table import data_registers, decode_header, header_registers, table_from_registers
from station.core.table.values import CorrectionTableData, TableAxis

WORDS = st.integers(min_value=0, max_value=0xFFFF)


def test_map_has_no_overlaps_and_fits_one_window():
    spans = sorted((r.address, r.end) for r in REGISTERS)
    assert all(b[0] >= a[1] for a, b in zip(spans, spans[1:]))
    assert spans[0][0] == 0 and spans[-1][1] <= WINDOW_SIZE == 128
    # the command block and the transfer block each fit one FC 16 request
    assert register_span("cmd_code", "cmd_token")[1] <= 123
    assert register_span("xfer_seq", "page_data")[1] <= 123
    assert TABLE_HEADER_REGISTERS <= REG["page_data"].count


@pytest.mark.parametrize("order,expected", [(WordOrder.BIG, [0x000F, 0x4240]),
                                            (WordOrder.LITTLE, [0x4240, 0x000F])])
def test_scaled_i32_word_order(order, expected):
    # 1.0 rad = 1 000 000 counts of 1e-6 = 0x000F4240
    assert encode("cmd_target", [1.0], order) == expected
    assert decode_i32_array(expected, 1e-6, order)[0] == np.float32(1.0)
    assert encode("cmd_target", [-1e-6], order) == [0xFFFF, 0xFFFF]


@pytest.mark.parametrize("order", list(WordOrder))
def test_u32_and_scaled_and_signed(order):
    words = encode("table_crc", 0x12345678, order)
    assert words == ([0x1234, 0x5678] if order is WordOrder.BIG else [0x5678, 0x1234])
    assert decode("table_crc", words, order) == 0x12345678
    assert encode("cmd_speed", 0.5) == [500]
    assert decode("cmd_speed", [500]) == pytest.approx(0.5)
    assert encode("cmd_elbow", -1) == [0xFFFF]
    assert decode("cmd_elbow", [0xFFFF]) == -1


@pytest.mark.parametrize("order", list(WordOrder))
def test_roundtrip_arrays(order):
    v = np.array([1.5, -2.25, 1e-6, 800.0, -3.141593, 0.0])
    assert np.allclose(decode("cmd_target", encode("cmd_target", v, order), order), v, rtol=0, atol=1e-12)
    assert np.allclose(decode_i32_array(encode_i32_array(v, 1e-6, order), 1e-6, order), v, rtol=1e-7)
    # vectorised and scalar encoders agree
    assert encode_i32_array(v, 1e-6, order) == encode("cmd_target", v, order)


def test_encode_rejects_what_does_not_fit():
    with pytest.raises(ValueError, match="does not fit"):
        encode("cmd_seq", 70000)
    with pytest.raises(ValueError, match="non-finite"):
        encode("cmd_target", [np.nan])
    with pytest.raises(ValueError, match="at most"):
        encode("cmd_target", np.zeros(7))
    with pytest.raises(ValueError, match="does not fit"):
        encode("cmd_target", [2200.0])  # beyond +-2147.48 at 1e-6 a count


def test_decode_rejects_wrong_count_and_range():
    with pytest.raises(RegisterDecodeError, match="expected 12"):
        decode("cmd_target", [0] * 11)
    with pytest.raises(RegisterDecodeError, match="outside"):
        decode("status", [70000])
    with pytest.raises(RegisterDecodeError, match="even"):
        decode_i32_array([1, 2, 3], 1e-6)


@settings(max_examples=200, deadline=None)
@given(st.sampled_from(REGISTERS), st.sampled_from(list(WordOrder)), st.data())
def test_fuzz_entry_decoders(reg, order, data):
    n = data.draw(st.integers(0, reg.n_registers + 2))
    words = data.draw(st.lists(st.integers(-5, 0x1FFFF), min_size=n, max_size=n))
    # Any outcome but a foreign exception is fine: a value, or the driver's own error.
    with contextlib.suppress(ControllerError):
        decode(reg, words, order)


_STATUS_N = register_span("ack_seq", "error_bound")[1]
_HDR_N = TABLE_HEADER_REGISTERS


@settings(max_examples=200, deadline=None)
@given(st.lists(WORDS, min_size=_STATUS_N, max_size=_STATUS_N))
def test_fuzz_status(words):
    s = ControllerStatus.from_registers(words)
    assert s.moving == bool(words[4] & 2)


@settings(max_examples=300, deadline=None)
@given(st.lists(WORDS, min_size=_HDR_N, max_size=_HDR_N), st.lists(WORDS, max_size=64),
       st.sampled_from(list(WordOrder)))
def test_fuzz_table_decoder_raises_only_driver_errors(header, data, order):
    try:
        t = table_from_registers(header, data, order)
    except ControllerError:
        return
    assert t.n_values * 2 == len(data)


@settings(max_examples=100, deadline=None)
@given(st.lists(WORDS, min_size=_HDR_N, max_size=_HDR_N), st.sampled_from(list(WordOrder)))
def test_fuzz_valid_looking_headers(header, order):
    header = list(header)
    header[0] = 2  # plausible format version to get deeper into the decoder
    header[29] = 0xFFF8  # value scale exponent -8
    header[1] = header[1] % 5
    with contextlib.suppress(ControllerError):  # only the driver's own error may escape
        decode_header(header, order)


@pytest.mark.parametrize("order", list(WordOrder))
def test_table_roundtrip_and_crc(order):
    rng = np.random.default_rng(1)
    axes = (TableAxis(100.0, 50.0, 3), TableAxis(-20.0, 10.0, 2), TableAxis(0.0, np.pi / 2, 4, periodic=True))
    t = CorrectionTableData(axes, rng.normal(0, 1e-3, (2, 3, 2, 4, 4)))
    t2 = table_from_registers(header_registers(t, order), data_registers(t, order), order)
    assert t2.same_as(t) and t2.crc32() == t.crc32()
    import zlib
    raw = np.rint(t.values.astype(float) / 1e-8).astype(">i4")
    assert t.crc32() == zlib.crc32(raw.tobytes())
    # the values are held on the wire's 1e-8 grid: a read back is bit for bit
    assert np.array_equal(t.values, (raw.astype(float) * 1e-8).astype(np.float32))
    data = data_registers(t, order)
    data[5] ^= 1
    from drivers.correction_table import TableError
    with pytest.raises(TableError, match="CRC-32"):
        table_from_registers(header_registers(t, order), data, order)
    changed = np.array(t.values)
    changed[1, 2, 1, 3, 0] += 1e-6
    t3 = CorrectionTableData(axes, changed)
    assert t3.crc32() != t.crc32() and "flat index" in t.first_difference(t3)


def test_interpolation_rule():
    axes = (TableAxis(0.0, 10.0, 3), TableAxis(0.0, np.pi / 2, 4, periodic=True))
    vals = np.zeros((1, 3, 4, 1))
    # linear in node index (mrad; a table holds at most +-21.47 rad or mm)
    vals[0, :, :, 0] = (np.arange(3)[:, None] * 10 + np.arange(4)[None, :]) * 1e-3
    t = CorrectionTableData(axes, vals)
    assert t.interpolate([5.0, 0.0])[0] == pytest.approx(5.0e-3)
    assert t.interpolate([20.0, np.pi / 4])[0] == pytest.approx(20.5e-3)
    # periodic wrap: between node 3 (value 3) and node 0 (value 0)
    assert t.interpolate([0.0, 3.5 * np.pi / 2])[0] == pytest.approx(1.5e-3, abs=1e-8)  # step on the 1e-6 grid
    assert t.interpolate([0.0, -np.pi / 4])[0] == pytest.approx(1.5e-3, abs=1e-8)
    from station.core.table.values import TableRangeError
    with pytest.raises(TableRangeError, match="outside"):
        t.interpolate([25.0, 0.0])


def test_values_beyond_the_wire_range_are_refused():
    from station.core.table.values import TableError
    with pytest.raises(TableError, match="21.47"):
        CorrectionTableData((TableAxis(0.0, 1.0, 1),), np.full((1, 1, 1), 30.0))
