"""Issue 39: a secret that is missing never turns authentication off silently."""

from __future__ import annotations

import pytest

from station.ui.cli.main import main


@pytest.mark.parametrize("text", ["", "  \n\t\n"])
def test_serve_refuses_an_empty_or_blank_token_file(tmp_path, capsys, text):
    token = tmp_path / "token"
    token.write_text(text)
    assert main(["serve", "--fleet", "postgresql://127.0.0.1:1/x", "--token-file", str(token)]) == 2
    err = capsys.readouterr().err
    assert "token file is empty" in err and "Traceback" not in err
