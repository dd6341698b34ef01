"""The software a report traces to: the station version the run was made with, the station that
built the report and its git commit when it runs from a checkout, and the Python, numpy and scipy
versions. Nothing here fails: a missing ``git``, a checkout without history or a package without
metadata each give "not known"."""

from __future__ import annotations

import datetime as dt
import platform
import subprocess
from importlib import metadata
from pathlib import Path

__all__ = ["commit_date", "git_commit", "software_rows"]

#: the station's source tree: a git checkout when it has a .git beside the package
_TREE = Path(__file__).resolve().parents[3]
_GIT_TIMEOUT_S = 3.0


def _git(tree: Path, *args: str) -> str | None:
    try:
        done = subprocess.run(["git", "-C", str(tree), *args], capture_output=True, text=True,
                              timeout=_GIT_TIMEOUT_S, check=False)
    except (OSError, subprocess.SubprocessError):  # no git, a hung git, a tree it cannot read
        return None
    return done.stdout.strip() if done.returncode == 0 else None


def git_commit(tree: Path = _TREE) -> str | None:
    """The checkout's commit (12 hex digits, "+ local changes" when its tracked files differ
    from it); None when ``tree`` is no git checkout or git is absent."""
    if not (tree / ".git").exists():
        return None
    commit = _git(tree, "rev-parse", "--short=12", "HEAD")
    if not commit:
        return None
    dirty = _git(tree, "status", "--porcelain", "--untracked-files=no")
    return f"{commit} + local changes" if dirty else commit


def _version(package: str) -> str:
    try:
        return metadata.version(package)
    except metadata.PackageNotFoundError:
        return "not known"


def software_rows(run_version: str, tree: Path = _TREE) -> list[tuple[str, str]]:
    """(item, value) in display order: the run's station version, the report's, its commit and
    the libraries the figures were computed with (those of the report's station: the
    identification is recomputed when the report is built)."""
    built = _version("calibration-station")
    commit = git_commit(tree)
    return [
        ("station version of the run", run_version or "not recorded"),
        ("report built by station", built),
        ("git commit", commit or "not known (not a git checkout, or git is absent)"),
        ("Python", platform.python_version()),
        ("numpy", _version("numpy")),
        ("scipy", _version("scipy")),
    ]


def commit_date(tree: Path = _TREE) -> dt.datetime | None:
    """The checkout's HEAD commit time (UTC); None when ``tree`` is no git checkout or git is absent."""
    if not (tree / ".git").exists():
        return None
    text = _git(tree, "show", "-s", "--format=%cI", "HEAD")
    try:
        return dt.datetime.fromisoformat(text).astimezone(dt.timezone.utc) if text else None
    except ValueError:
        return None
