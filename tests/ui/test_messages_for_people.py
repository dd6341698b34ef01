"""Messages for people (issue 33): a serial URL pyserial rejects is a configuration error naming
the key, not "'<=' not supported between instances of 'int' and 'NoneType'"; pymodbus' own log
lines go into the station's log, not onto the terminal."""

from __future__ import annotations

import logging
from pathlib import Path

import pytest

from station.cell.session.calibrate import check_probe_url
from station.errors import ConfigError
from station.ui.cli.main import main
from station.ui.cli.process.library_log import route_library_logs


@pytest.mark.parametrize("url, why", [
    ("socket://", ""), ("socket://host", ""), ("socket://localhost:99999", ""), ("rfc2217://", ""),
    ("bogus://x", "protocol 'bogus' not known"),
])
def test_a_serial_url_pyserial_rejects_is_a_config_error_naming_the_key(url, why):
    with pytest.raises(ConfigError) as info:
        check_probe_url(url)
    msg = str(info.value)
    assert msg.startswith(f"[devices] probe_head = {url!r}: not a serial port pyserial can open"), msg
    assert "socket://HOST:PORT" in msg and why in msg
    for python in ("NoneType", "'<='", "TypeError", "()"):
        assert python not in msg, msg


@pytest.mark.parametrize("url", ["/dev/ttyUSB0", "COM3", "socket://localhost:5000", "rfc2217://10.0.0.1:4001",
                                 "loop://"])
def test_a_usable_serial_url_passes(url):
    check_probe_url(url)


def test_station_check_names_the_key(tmp_path: Path, capsys):
    cfg = tmp_path / "cell.toml"
    assert main(["init", str(cfg)]) == 0
    text = cfg.read_text()
    lines = [('probe_head = "socket://"' if ln.startswith("probe_head =") else
              'controller = "127.0.0.1:1"' if ln.startswith("controller =") else ln) for ln in text.splitlines()]
    cfg.write_text("\n".join(lines) + "\n")
    capsys.readouterr()
    rc = main(["check", str(cfg)])
    out = capsys.readouterr()
    text = out.out + out.err
    assert rc == 2, text
    assert "[devices] probe_head = 'socket://'" in text and "NoneType" not in text, text
    for python in ("ConfigError", "ControllerConnectionError", "connect()"):  # no type names, no API words
        assert python not in text, text


def test_pymodbus_log_lines_go_to_the_station_log_not_the_terminal(capfd, caplog):
    route_library_logs()
    route_library_logs()  # idempotent: one handler
    lib = logging.getLogger("pymodbus")
    assert not lib.propagate and len(lib.handlers) == 1
    capfd.readouterr()
    with caplog.at_level(logging.DEBUG, logger="station.devices"):
        logging.getLogger("pymodbus.logging").error("Invalid Modbus protocol id: %s", 21584)
    out, err = capfd.readouterr()
    assert "Invalid Modbus protocol id" not in out + err
    records = [r for r in caplog.records if r.name == "station.devices.pymodbus"]
    assert len(records) == 1 and records[0].levelno == logging.DEBUG
    assert records[0].getMessage() == "pymodbus.logging error: Invalid Modbus protocol id: 21584"
