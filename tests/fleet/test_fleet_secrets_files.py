"""Issue 39, files and secrets: a password in [fleet] url in any spelling libpq reads is refused
without being shown; the OPC UA users file refuses control characters and, with the server key,
is created mode 600 from its first byte; odd robot keys are a 404 or a link that stays whole."""

from __future__ import annotations

import os
import shutil
import stat
from pathlib import Path

import pytest
from fleet_runs import clock, days_ago, publication
from starlette.testclient import TestClient

from station.errors import ConfigError
from station.fleet import store
from station.ui.cli.main import main
from station.ui.dashboard.app import create_app
from station.ui.opcua.security import add_user, make_certificate, read_users

ROOT = Path(__file__).resolve().parents[2]
SECRET = "hunter2-Zq"


@pytest.mark.parametrize("url", [
    f"postgresql://plant@db/fleet?pass%77ord={SECRET}",   # libpq decodes %77: 'password'
    f"postgresql://plant:{SECRET}@db/fleet",
    "postgresql://plant:%68unter2-Zq@db/fleet",          # the password itself percent-encoded
    f"postgresql://db/fleet?password={SECRET}",
    f"postgres://db/fleet?sslpassword={SECRET}",
    f"host=db dbname=fleet password = {SECRET}",
    f"host=db dbname=fleet password='{SECRET}'",
])
def test_a_password_in_any_spelling_is_refused_and_never_shown(tmp_path, capsys, url):
    cell = tmp_path / "cell"
    shutil.copytree(ROOT / "examples" / "scara600", cell)
    with (cell / "cell.toml").open("a", encoding="utf-8") as f:
        f.write(f"\n[fleet]\nurl = '''{url}'''\n")  # a TOML literal string: the URL as written
    assert main(["fleet", str(cell / "cell.toml")]) == 2
    err = capsys.readouterr().err
    assert "holds a password" in err and "Traceback" not in err
    assert SECRET not in err and "unter2" not in err


def test_a_url_without_a_password_is_accepted(tmp_path):
    from station.cell.config.cell_config import load_config

    cell = tmp_path / "cell"
    shutil.copytree(ROOT / "examples" / "scara600", cell)
    with (cell / "cell.toml").open("a", encoding="utf-8") as f:
        f.write('\n[fleet]\nurl = "postgresql://plant@db/fleet?passfile=/etc/station/pgpass"\n')
    assert load_config(str(cell / "cell.toml")).fleet.url.endswith("pgpass")


@pytest.mark.parametrize("name", ["mes\x00", "mes\x1b[31m", "line\x7f", "tab\tname", "a\u2028b"])
def test_add_user_refuses_control_characters_and_leaves_the_file_readable(tmp_path, name):
    users = tmp_path / "users.toml"
    add_user(users, "mes", "operator", "pw")
    before = users.read_bytes()
    with pytest.raises(ConfigError, match="plain user name"):
        add_user(users, name, "observer", "pw")
    assert users.read_bytes() == before
    add_user(users, "plc", "observer", "pw2")  # a later --add-user still works
    assert [a.name for a in read_users(users).accounts] == ["mes", "plc"]


def test_secrets_are_mode_600_from_their_creation(tmp_path, monkeypatch):
    """Every descriptor the users file and the server key are written through was created 600
    (the old write-then-chmod left them world-readable in between, under a umask of 022)."""
    created: list[tuple[str, int]] = []
    real_open = os.open

    def spy(path, flags, mode=0o777, *args, **kwargs):
        if flags & os.O_CREAT:
            created.append((str(path), mode))
        return real_open(path, flags, mode, *args, **kwargs)

    monkeypatch.setattr(os, "open", spy)
    old = os.umask(0o022)
    try:
        add_user(tmp_path / "users.toml", "mes", "operator", "pw")
        make_certificate(tmp_path / "own" / "cert.der", tmp_path / "own" / "private" / "key.pem", "urn:x", "localhost",
                         server=True)
    finally:
        os.umask(old)
    secrets_made = [(p, m) for p, m in created if "users.toml" in p or "key.pem" in p]
    assert len(secrets_made) == 2 and all(m == 0o600 for _, m in secrets_made), created
    for f in (tmp_path / "users.toml", tmp_path / "own" / "private" / "key.pem"):
        assert stat.S_IMODE(f.stat().st_mode) == 0o600
    assert not list(tmp_path.rglob("*.tmp"))


def test_a_serial_of_dots_is_refused(tmp_path, capsys):
    cell = tmp_path / "cell"
    shutil.copytree(ROOT / "examples" / "scara600", cell)
    text = (cell / "cell.toml").read_text(encoding="utf-8")
    (cell / "cell.toml").write_text(text.replace("[cell]\n", '[cell]\nrobot_serial = ".."\n', 1), encoding="utf-8")
    assert main(["fleet", str(cell / "cell.toml")]) == 2
    assert "dots only" in capsys.readouterr().err


def test_odd_robot_keys_are_a_404_or_a_whole_link(fleet_db):
    odd = "../../runs/x"
    with store.connect(fleet_db.station_url) as c:
        store.insert_publication(c, publication(odd, "calibration", days_ago(3), after_um=12.0))
    with TestClient(create_app(fleet_db.dashboard_url, clock=clock), raise_server_exceptions=False) as client:
        assert client.get("/robots/%00").status_code == 404  # was 503: the store refused the NUL
        assert client.get("/robots/a%01b").status_code == 404
        page = client.get("/").text
        assert 'href="/robots/..%2F..%2Fruns%2Fx"' in page  # one segment: no browser rewrites it
        robot = client.get("/robots/..%2F..%2Fruns%2Fx")
        assert robot.status_code == 200 and "runs/x" in robot.text
