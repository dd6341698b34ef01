"""The users file, the password hashes and the role check, without a server; and the command
line's refusals before anything is served."""

from __future__ import annotations

import pytest
from asyncua import ua
from asyncua.common.utils import Buffer
from asyncua.ua.ua_binary import struct_to_binary

from station.errors import ConfigError
from station.ui.cli.main import main
from station.ui.opcua.security import (
    StationRuleset,
    StationUser,
    StationUserManager,
    add_user,
    check_password,
    hash_password,
    read_users,
)
from tests.opcua.clients import CONFIG


def test_passwords_are_salted_scrypt_hashes_never_text(tmp_path) -> None:
    a, b = hash_password("shift-change"), hash_password("shift-change")
    assert a != b and a.startswith("scrypt$") and "shift-change" not in a  # salted
    assert check_password("shift-change", a) and not check_password("shift-chang", a)
    users = tmp_path / "users.toml"
    add_user(users, "mes", "operator", "shift-change")
    assert "shift-change" not in users.read_text() and users.stat().st_mode & 0o077 == 0
    manager = StationUserManager(read_users(users))
    user = manager.get_user(None, username="mes", password="shift-change")
    assert user is not None and user.station_role == "operator"  # type: ignore[attr-defined]
    assert manager.get_user(None, username="mes", password="wrong") is None
    assert manager.get_user(None) is None  # anonymous
    with pytest.raises(ConfigError, match="exists already"):
        add_user(users, "mes", "observer", "other")


def test_a_users_file_with_a_plain_password_is_refused(tmp_path) -> None:
    users = tmp_path / "users.toml"
    users.write_text('[[user]]\nname = "mes"\nrole = "operator"\npassword = "hunter2"\n')
    with pytest.raises(ConfigError, match="never the password itself"):
        read_users(users)
    users.write_text('[[user]]\nname = "mes"\nrole = "admin"\npassword = "x"\n')
    with pytest.raises(ConfigError, match="role must be one of observer, operator"):
        read_users(users)


def _call_body(*methods: ua.NodeId) -> Buffer:
    """A Call request's body as the server receives it (binary, undecoded)."""
    params = ua.CallParameters(MethodsToCall=[ua.CallMethodRequest(ObjectId=ua.NodeId("CalibrationStation", 7),
                                                                   MethodId=m) for m in methods])
    return Buffer(struct_to_binary(params))


def test_the_role_is_checked_method_by_method() -> None:
    start = ua.NodeId("CalibrationStation.StartRecheck", 7)
    latest = ua.NodeId("CalibrationStation.Results.GetLatestResult", 7)
    rules = StationRuleset({start})
    watch, line = StationUser(name="watch", station_role="observer"), StationUser(name="line", station_role="operator")
    call = ua.NodeId(ua.ObjectIds.CallRequest_Encoding_DefaultBinary)
    read = ua.NodeId(ua.ObjectIds.ReadRequest_Encoding_DefaultBinary)
    write = ua.NodeId(ua.ObjectIds.WriteRequest_Encoding_DefaultBinary)
    body = _call_body(latest, start)
    assert not rules.check_validity(watch, call, body)
    assert body.cur_pos == 0  # the server still decodes the request after the check
    assert rules.check_validity(watch, call, _call_body(latest))
    assert rules.check_validity(line, call, _call_body(latest, start))
    assert rules.check_validity(watch, read, None)
    assert not rules.check_validity(line, write, None)  # nobody writes
    assert not rules.check_validity(watch, call, Buffer(b"\x01"))  # undecodable: refused


def test_serve_refuses_to_start_without_users_or_certificate(tmp_path, capsys) -> None:
    assert main(["serve", "--opcua", str(CONFIG), "--simulated"]) == 2
    assert "--users" in capsys.readouterr().err
    users = tmp_path / "users.toml"
    add_user(users, "mes", "operator", "pw")
    assert main(["serve", "--opcua", str(CONFIG), "--users", str(users), "--pki", str(tmp_path / "none")]) == 2
    assert "--init-pki" in capsys.readouterr().err
