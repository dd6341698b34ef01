"""numpy's and scipy's warnings under a command: silenced where the station checks, else one line."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from station.ui.cli import main as cli


def _command_warning(kind: str):
    def run(args) -> int:
        if kind == "overflow":
            np.array([1e308]) * 10.0  # RuntimeWarning: overflow encountered in multiply
            np.log(np.array([0.0]))  # divide by zero encountered in log
        else:
            from scipy.linalg import LinAlgWarning

            for _ in range(3):
                warnings.warn("Ill-conditioned matrix (rcond=1e-20): result may not be accurate.",
                              LinAlgWarning, stacklevel=1)
        return 0
    return run


@pytest.mark.parametrize("kind", ["overflow", "linalg"])
def test_numerical_warnings_never_reach_stderr_in_their_raw_form(kind, monkeypatch, capsys):
    monkeypatch.setattr(cli, "_command", lambda spec: _command_warning(kind))
    assert cli.main(["runs"]) == 0
    err = capsys.readouterr().err
    assert ".py:" not in err and "warnings.warn" not in err  # no file:line form
    if kind == "overflow":
        assert err == ""  # expected: the station checks results for finiteness
    else:
        lines = [ln for ln in err.splitlines() if ln]
        assert lines == ["station: note: Ill-conditioned matrix (rcond=1e-20): result may not be accurate. "
                         "(LinAlgWarning)"]  # once, in the station's own words


def test_the_policy_is_undone_after_the_command(monkeypatch):
    monkeypatch.setattr(cli, "_command", lambda spec: _command_warning("overflow"))
    cli.main(["runs"])
    with pytest.warns(RuntimeWarning, match="overflow"):
        np.array([1e308]) * 10.0
