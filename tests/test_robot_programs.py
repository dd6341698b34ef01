"""The robot programs under robot-programs/ stay true to the register map.

Each program declares the map's numbers as named constants (URScript ``global NAME = n``, SPEL+
``#define NAME n``): ``R_<REGISTER>`` window offsets, ``H_<HEADER ENTRY>`` table-header offsets,
``C_`` command codes, ``X_`` transfer operations, ``E_`` error codes, ``S_`` status bits, ``CS_``
correction states, ``INFO_`` info pages and the map's sizes. These tests parse them and compare
them with :mod:`drivers.controller_map`, so that a change of the map fails here until the programs
follow it.
"""

from __future__ import annotations

import re
import zlib
from pathlib import Path

import pytest

from drivers import controller_map as cm
from drivers.correction_table import n_value_pages

ROOT = Path(__file__).resolve().parents[1] / "robot-programs"
UR = ROOT / "ur" / "station_link.script"
EPSON = ROOT / "epson" / "StationLink.prg"

_DECL = {UR: re.compile(r"^\s*global\s+([A-Z][A-Z0-9_]*)\s*=\s*(-?\d+)\s*$", re.M),
         EPSON: re.compile(r"^\s*#define\s+([A-Z][A-Z0-9_]*)\s+(-?\d+)\s*$", re.M)}
_COMMENT = {UR: "#", EPSON: "'"}
_PREFIXES = ("R", "H", "C", "X", "E", "S", "CS", "INFO")


def constants(path: Path) -> dict[str, int]:
    """The program's integer constants by name (a name declared twice is an error)."""
    out: dict[str, int] = {}
    for name, value in _DECL[path].findall(path.read_text()):
        assert name not in out, f"{path.name}: {name} declared twice"
        out[name] = int(value)
    return out


def code_lines(path: Path) -> str:
    """The program without its comment lines and trailing comments (nothing in the programs
    quotes the comment character inside a string)."""
    c = _COMMENT[path]
    return "\n".join(line.split(c, 1)[0] for line in path.read_text().splitlines()
                     if not line.lstrip().startswith(c))


def expected_constants(registers=cm.REGISTERS, with_header: bool = True) -> dict[str, int]:
    """What a program must declare, from the map."""
    exp = {f"R_{r.name.upper()}": r.address for r in registers}
    exp |= {f"C_{c.name}": int(c) for c in cm.Command}
    exp |= {f"X_{x.name}": int(x) for x in cm.XferOp}
    exp |= {f"E_{e.name}": int(e) for e in cm.ErrorCode}
    exp |= {f"S_{s.name}": int(s) for s in cm.StatusBit}
    exp |= {f"CS_{s.name}": int(s) for s in cm.CorrectionState}
    exp |= {f"INFO_{k.upper()}": n for k, (n, _r) in cm.INFO_PAGES.items()}
    exp |= {"MAP_VERSION": cm.MAP_VERSION, "WINDOW_SIZE": cm.WINDOW_SIZE,
            "PAGE_DATA_REGISTERS": cm.PAGE_DATA_REGISTERS, "ORDER_CHECK_VALUE": cm.ORDER_CHECK_VALUE}
    if with_header:
        exp |= {f"H_{r.name.upper()}": r.address for r in cm.TABLE_HEADER}
        exp |= {"MAX_TABLE_VALUES": cm.MAX_TABLE_VALUES, "PAGE_VALUES": cm.PAGE_VALUES,
                "MAX_PAGES": n_value_pages(cm.MAX_TABLE_VALUES),
                "TABLE_FORMAT_VERSION": cm.TABLE_FORMAT_VERSION,
                "TABLE_HEADER_REGISTERS": cm.TABLE_HEADER_REGISTERS}
    return exp


def mismatches(declared: dict[str, int], expected: dict[str, int]) -> list[str]:
    """Every map constant the program lacks or declares with another value, and every map-named
    constant it declares that the map does not have."""
    out = [f"{k}: program {declared.get(k)}, map {v}" for k, v in expected.items() if declared.get(k) != v]
    out += [f"{k}: not in the map" for k in declared
            if k.split("_", 1)[0] in _PREFIXES and k not in expected and not k.startswith("SLOT_")]
    return out


PROGRAMS = [pytest.param(UR, False, id="ur"), pytest.param(EPSON, True, id="epson")]


@pytest.mark.parametrize("path,with_header", PROGRAMS)
def test_program_constants_equal_the_map(path: Path, with_header: bool) -> None:
    bad = mismatches(constants(path), expected_constants(with_header=with_header))
    assert not bad, f"{path.name} does not follow drivers/controller_map.py: " + "; ".join(bad)


@pytest.mark.parametrize("path,with_header", PROGRAMS)
def test_program_uses_only_declared_map_names(path: Path, with_header: bool) -> None:
    declared = constants(path)
    used = set(re.findall(r"\b((?:R|H|C|X|E|S|CS|INFO)_[A-Z0-9_]+)\b", code_lines(path)))
    assert used - set(declared) == set(), f"{path.name} uses undeclared names {sorted(used - set(declared))}"
    # every register of the map is used somewhere, not only declared
    unused = sorted(n for n in declared if n.startswith("R_") and len(re.findall(rf"\b{n}\b", code_lines(path))) < 2)
    assert not unused, f"{path.name}: registers declared but never used: {unused}"


def test_a_changed_map_is_caught() -> None:
    """The comparison fails when the map moves a register or adds one the program lacks."""
    moved = tuple(cm.Register(r.name, r.address + 1, r.type, r.count, r.scale, r.unit, r.access, r.meaning)
                  if r.name == "status" else r for r in cm.REGISTERS)
    bad = mismatches(constants(EPSON), expected_constants(moved))
    assert bad == ["R_STATUS: program 40, map 41"]
    added = (*cm.REGISTERS, cm.Register("new_reg", 127, cm.RegType.U16, 1, 1.0, "", "r", ""))
    assert mismatches(constants(UR), expected_constants(added, with_header=False)) == \
        ["R_NEW_REG: program None, map 127"]
    assert "MAP_VERSION: program 3, map 4" in mismatches(
        constants(UR), {**expected_constants(with_header=False), "MAP_VERSION": 4})


def test_ur_program_hosts_the_map_at_the_general_purpose_registers() -> None:
    text = code_lines(UR)
    assert constants(UR)["BASE"] == 128
    assert "read_port_register(BASE + off)" in text and "write_port_register(BASE + off, v)" in text
    # a UR always applies its factory calibration: the program says so
    assert re.search(r"wr\(R_CORRECTION_STATE, CS_VENDOR\)", text)
    # no table lives on this controller: none of the table commands succeeds in storing one
    assert re.search(r"code == C_TABLE_STAGE:\s*\n\s*refuse\(seq, E_TABLE_SHAPE_INVALID", text)
    assert re.search(r"code == C_TABLE_ACTIVATE:\s*\n\s*refuse\(seq, E_TABLE_NOT_STAGED", text)
    assert re.search(r"code == C_TABLE_ROLLBACK:\s*\n\s*refuse\(seq, E_NO_PREVIOUS_TABLE", text)


def _crc_split_halves(data: bytes, poly_hi: int, poly_lo: int) -> int:
    """The Epson program's CRC-32 (CrcInit / CrcByte / CrcEnd), transliterated: the state and
    the table in two 16-bit halves."""
    tab = []
    for n in range(256):
        hi, lo = 0, n
        for _ in range(8):
            c = lo & 1
            lo = (lo >> 1) | ((hi & 1) << 15)
            hi >>= 1
            if c:
                hi, lo = hi ^ poly_hi, lo ^ poly_lo
        tab.append((hi, lo))
    chi, clo = 0xFFFF, 0xFFFF
    for b in data:
        idx = (clo & 0xFF) ^ b
        clo = ((clo >> 8) | ((chi & 0xFF) << 8)) ^ tab[idx][1]
        chi = (chi >> 8) ^ tab[idx][0]
    return ((chi ^ 0xFFFF) << 16) | (clo ^ 0xFFFF)


def test_crc_constants_are_the_zlib_polynomial() -> None:
    epson = code_lines(EPSON)
    hi = re.search(r"hi = hi Xor &H([0-9A-F]{4})", epson)
    lo = re.search(r"lo = lo Xor &H([0-9A-F]{4})", epson)
    assert hi and lo
    check = b"123456789"
    assert _crc_split_halves(check, int(hi.group(1), 16), int(lo.group(1), 16)) == zlib.crc32(check) == 0xCBF43926
    page = bytes(range(256)) * 3
    assert _crc_split_halves(page, int(hi.group(1), 16), int(lo.group(1), 16)) == zlib.crc32(page)
    ur = re.search(r"CRC_POLY_BITS = integer_to_binary_list\((-?\d+)\)", code_lines(UR))
    assert ur and int(ur.group(1)) & 0xFFFFFFFF == 0xEDB88320


@pytest.mark.parametrize("path", [UR, EPSON], ids=["ur", "epson"])
def test_program_header_states_what_was_and_was_not_checked(path: Path) -> None:
    head = path.read_text()[:8000]
    for phrase in ("map version 3", "WHAT WAS CHECKED", "WHAT WAS NOT DONE", "NOT run on a real controller",
                   "station conformance"):
        assert phrase in head, f"{path.name}: header lacks {phrase!r}"
