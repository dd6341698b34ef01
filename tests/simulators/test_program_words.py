"""The simulated robot program's own register words (simulators/program_words.py) against the
driver's codec (drivers/controller_map.py, drivers/correction_table.py) and the station's table
(station/core/table/values.py): two implementations of docs/protocols.md written apart, held to
each other by round trips and to the document by its worked examples. A slip in one of them (a
word order, a sign, a CRC byte order, an interpolation corner) fails here, where a simulator
that imported the driver's codec would agree with it."""

from __future__ import annotations

import zlib

import numpy as np
import pytest

from drivers.controller_map import REG, REGISTERS, TABLE_HDR, RegType, WordOrder, decode, encode, registers_crc32
from drivers.correction_table import decode_header, header_registers, value_pages
from simulators.program_words import (
    OutsideTable,
    ProgramTable,
    counts_from_words,
    crc32_of_counts,
    crc32_of_registers,
    get_value,
    header_page,
    put_value,
    read_header,
    value_page_words,
    words_from_counts,
)
from station.core.table.values import CorrectionTableData, TableAxis, TableRangeError

ORDERS = (WordOrder.BIG, WordOrder.LITTLE)


def test_the_documents_worked_examples():
    # docs/protocols.md, "Data types and word order": 1.0 rad = 1 000 000 = 0x000F4240 ->
    # BIG [0x000F, 0x4240], LITTLE [0x4240, 0x000F]; -50 mm = -50 000 000 = 0xFD050F80 -> BIG [0xFD05, 0x0F80]
    joint = REG["cmd_target"]
    regs = [0] * 128
    put_value(regs, joint, [1.0], WordOrder.BIG)
    assert regs[joint.address:joint.address + 2] == [0x000F, 0x4240]
    put_value(regs, joint, [1.0], WordOrder.LITTLE)
    assert regs[joint.address:joint.address + 2] == [0x4240, 0x000F]
    put_value(regs, joint, [-50.0], WordOrder.BIG)
    assert regs[joint.address:joint.address + 2] == [0xFD05, 0x0F80]
    assert words_from_counts([-50_000_000], WordOrder.BIG) == [0xFD05, 0x0F80]
    # "Check value: CRC-32 of "123456789" is 0xCBF43926": the algorithm; the page CRC over the
    # registers 0x3132 0x3334 0x3536 0x3738 is that CRC over the bytes "12345678", high byte first
    assert zlib.crc32(b"123456789") == 0xCBF43926
    assert crc32_of_registers([0x3132, 0x3334, 0x3536, 0x3738]) == zlib.crc32(b"12345678")
    # the table CRC over counts 0x31323334 and 0x35363738 is that CRC again, word order or not
    assert crc32_of_counts([0x31323334, 0x35363738]) == zlib.crc32(b"12345678")


def _random_value(rng, reg):
    """A value of ``reg`` that fits its type, scaled; near the type's bounds a third of the time."""
    t = reg.type
    lo, hi = {RegType.U16: (0, 0xFFFF), RegType.I16: (-0x8000, 0x7FFF),
              RegType.U32: (0, 0xFFFFFFFF), RegType.I32: (-0x80000000, 0x7FFFFFFF)}[t]
    raw = rng.integers(lo, hi, endpoint=True, size=reg.count)
    edge = rng.random(reg.count) < 0.33
    raw[edge] = rng.choice([lo, hi, lo + 1, hi - 1, 0, -1 if lo < 0 else 1], size=int(edge.sum()))
    return raw * reg.scale if reg.scale != 1 else raw


@pytest.mark.parametrize("order", ORDERS, ids=lambda o: o.value)
def test_every_entry_of_the_map_round_trips_between_driver_and_program(order):
    rng = np.random.default_rng(33)
    for reg in (*REGISTERS, *TABLE_HDR.values()):
        for _ in range(40):
            value = _random_value(rng, reg)
            driver_words = encode(reg, value, order)
            regs = [0] * (reg.address + reg.n_registers)
            put_value(regs, reg, value, order)
            assert regs[reg.address:] == driver_words, reg.name  # the same words, both ways written
            back = get_value(regs, reg, order)
            assert np.array_equal(np.atleast_1d(back), np.atleast_1d(decode(reg, driver_words, order))), reg.name


@pytest.mark.parametrize("order", ORDERS, ids=lambda o: o.value)
def test_i32_arrays_and_the_table_crc_agree_with_the_driver(order):
    rng = np.random.default_rng(7)
    counts = np.concatenate([rng.integers(-2**31, 2**31 - 1, 500, endpoint=True), [-2**31, 2**31 - 1, 0, -1, 1]])
    words = words_from_counts(counts, order)
    from drivers.controller_map import decode_i32_raw, encode_i32_array, raw_crc32

    assert words == encode_i32_array(counts * 1e-8, 1e-8, order)
    assert np.array_equal(counts_from_words(words, order), decode_i32_raw(words, order))
    assert crc32_of_counts(counts) == raw_crc32(counts)
    assert crc32_of_registers(words) == registers_crc32(words)


def _table(rng, shape=(4, 3, 2, 5), n_joints=4, n_configs=2, periodic_last=True) -> CorrectionTableData:
    axes = tuple(TableAxis(round(float(rng.uniform(-400, 400)), 6), round(float(rng.uniform(0.5, 60)), 6), n,
                           periodic_last and k == len(shape) - 1) for k, n in enumerate(shape))
    values = (np.rint(rng.normal(0, 1e-3, (n_configs, *shape, n_joints)) / 1e-8) * 1e-8).astype(np.float32)
    return CorrectionTableData(axes, values)


@pytest.mark.parametrize("order", ORDERS, ids=lambda o: o.value)
def test_a_table_travels_from_the_driver_to_the_program_and_back_bit_for_bit(order):
    rng = np.random.default_rng(5)
    t = _table(rng)
    h = read_header(header_registers(t, order), order)  # the program reads the driver's header page
    assert h is not None and h["crc"] == t.crc32() and h["n_values"] == t.values.size
    counts = counts_from_words([w for page in value_pages(t, order) for w in page], order)
    kept = ProgramTable(h["axes"], counts.reshape(t.values.shape))
    assert kept.same_as(t) and t.same_as(kept) and kept.crc32() == t.crc32()
    # and the slot reads: the program's regenerated pages are the driver's, word for word
    assert header_page(kept, order) == header_registers(t, order)
    assert value_page_words(kept, order) == value_pages(t, order)
    assert decode_header(header_page(kept, order), order)["crc"] == t.crc32()


def test_a_header_the_program_must_refuse():
    t = _table(np.random.default_rng(1))
    good = header_registers(t)
    for name, value in (("table_format", 1), ("table_value_scale_exp", -6), ("table_n_axes", 5),
                        ("table_n_configs", 3), ("table_n_values", t.values.size + 1), ("table_n_joints", 0)):
        bad = list(good)
        put_value(bad, TABLE_HDR[name], value, WordOrder.BIG)
        assert read_header(bad, WordOrder.BIG) is None, name
    bad = list(good)
    put_value(bad, TABLE_HDR["table_step"], [0.0], WordOrder.BIG)  # a step of 0 on axis 0
    assert read_header(bad, WordOrder.BIG) is None


def test_the_program_interpolates_as_the_station_predicts():
    # docs/protocols.md, "Interpolation rule": the program's own implementation and the station's
    # reference one agree at random points, at nodes, on the periodic seam and at the edges
    rng = np.random.default_rng(11)
    for shape in ((4, 3, 2, 5), (6,), (3, 1, 4), (2, 2, 2, 8)):
        t = _table(rng, shape=shape, n_configs=2)
        h = read_header(header_registers(t), WordOrder.BIG)
        assert h is not None
        kept = ProgramTable(h["axes"], counts_from_words([w for p in value_pages(t) for w in p],
                                                         WordOrder.BIG).reshape(t.values.shape))
        lo = np.array([a.start for a in t.axes])
        span = np.array([(a.count - (0 if a.periodic else 1)) * a.step for a in t.axes])
        for _ in range(300):
            u = rng.uniform(-0.5, 1.5, len(shape)) if rng.random() < 0.2 else rng.uniform(0, 1, len(shape))
            node = rng.random() < 0.2
            p = lo + (np.round(u * np.array([a.count for a in t.axes])) / np.array([a.count for a in t.axes])
                      if node else u) * span
            config = int(rng.integers(0, 2))
            try:
                want = t.interpolate(p, config)
            except TableRangeError:
                with pytest.raises(OutsideTable):
                    kept.correction(p, config)
                continue
            # the station holds the values as float32 (what a read back decodes to), the program as
            # integer counts: they differ by float32's rounding, 6e-8 of the largest value
            assert np.allclose(kept.correction(p, config), want, rtol=0, atol=1e-7 * np.abs(t.values).max()), (shape, p)
