"""Which cell a run was measured on: a fingerprint stored with the run, so that a resume can
refuse data from another cell (another body, set-up, robot file, head, limits or simulated seed).
What only post-processes the measurements (``POST_PROCESSING``: the identification's settings,
the correction grid, tolerances, names in the report) may change: a resume then reuses every
measurement and says so (:func:`resume_note`).

The fingerprint hashes every section of the configuration except ``[devices]`` (a port may be
renamed between two attempts without changing the cell) plus the robot model as loaded (so an
edited robot file counts even though the configuration names the same path).

Files count by what they hold, never by where they lie (issue 37): the keys that name a file
(``[robot] model``, ``[body] file``, ``[head] file``) leave the sections' digests, and the loaded
robot, body points and head stand for them. A cell folder moved or copied with unchanged files
(a rehearsal writes their paths absolute) is the same cell. Fingerprints stored before carry no
:data:`BY_CONTENT` entry and are compared as they were made (paths included).
"""

from __future__ import annotations

import hashlib
import json
import tomllib
from collections.abc import Collection, Iterable
from typing import Any

import numpy as np

from station.cell.config.cell_config import CellConfig
from station.cell.plan.steps import StepKind
from station.errors import ConfigError

#: sections of the configuration that may change between attempts of one run: the devices' ports,
#: and where results go (``[fleet]``: the plant's store, never the cell; issue 39: adding it, as
#: README's plant recipe says, made every recheck refuse the earlier calibrations)
_IGNORED = ("devices", "fleet")


def _digest(obj: Any) -> str:
    return hashlib.sha256(json.dumps(obj, sort_keys=True, default=str).encode()).hexdigest()[:16]


#: the keys that name a file (section, key): their content is fingerprinted, not their path
FILE_KEYS = (("robot", "model"), ("body", "file"), ("head", "file"))
#: the entry a content fingerprint carries (one stored before compares paths too)
BY_CONTENT = ("files", "by content")


def without_file_paths(data: dict[str, Any]) -> dict[str, Any]:
    """The parsed configuration without the keys that name a file (:data:`FILE_KEYS`)."""
    out = dict(data)
    for section, key in FILE_KEYS:
        if isinstance(out.get(section), dict) and key in out[section]:
            out[section] = {k: v for k, v in out[section].items() if k != key}
    return out


#: the keys that only judge a stored reading (section, key): each gets its own digest, so that a
#: resume may change it (issue 37 §4: a bound too tight for the head refused readings whose pose
#: was solved and stored; the stored readings are judged again, nothing is measured again)
JUDGING_KEYS = (("plan", "max_residual_um"),)
#: the entry a fingerprint with the judging keys apart carries (one stored before has them in [plan])
JUDGED_APART = ("judged apart", "plan.max_residual_um")


def _judging_apart(data: dict[str, Any]) -> tuple[dict[str, Any], dict[str, str]]:
    """``data`` without :data:`JUDGING_KEYS`, and their digests as ``[section] key`` entries."""
    out, apart = dict(data), {}
    for section, key in JUDGING_KEYS:
        table = out.get(section)
        value = table.get(key) if isinstance(table, dict) else None
        if isinstance(table, dict):
            out[section] = {k: v for k, v in table.items() if k != key}
        apart[f"[{section}] {key}"] = _digest(value)
    return out, apart


def fingerprint(cfg: CellConfig, by_content: bool = True, judged_apart: bool = True) -> dict[str, str]:
    """Section name → digest, plus ``robot model`` for the loaded robot (and ``body points``,
    ``probe head`` for a body or head file). ``by_content=False``: the fingerprint as made before
    issue 37, with the files' paths in their sections' digests (to compare with a stored one);
    ``judged_apart=False``: as made before the judging keys had their own entries."""
    try:
        data = tomllib.loads(cfg.source_text) if cfg.source_text else {}
    except tomllib.TOMLDecodeError:  # pragma: no cover - a CellConfig was parsed from this text
        data = {}
    hashed = without_file_paths(data) if by_content else data
    apart: dict[str, str] = {}
    if judged_apart:
        hashed, apart = _judging_apart(hashed)
        apart[JUDGED_APART[0]] = JUDGED_APART[1]
    out = {f"[{k}]": _digest(v) for k, v in hashed.items() if k not in _IGNORED} | apart
    if by_content:
        out[BY_CONTENT[0]] = BY_CONTENT[1]
    m = cfg.model
    out["robot model"] = _digest({"name": m.name, "types": list(m.joint_types),
                                  "nominal": np.round(np.asarray(m.nominal), 12).tolist(),
                                  "limits": np.round(np.asarray(m.joint_limits), 12).tolist()})
    body = data.get("body")
    if isinstance(body, dict) and "file" in body:  # the CMM report as read: an edited body file counts
        out["body points"] = _digest({"ids": list(cfg.point_ids), "poses": np.round(cfg.body_points, 9).tolist(),
                                      "sigma": np.round(np.asarray(cfg.body_sigma), 12).tolist()})
    head = data.get("head")
    if isinstance(head, dict) and "file" in head and cfg.head is not None:  # the head file as read
        g = cfg.head
        out["probe head"] = _digest({k: np.round(np.asarray(v, dtype=float), 9).tolist() for k, v in (
            ("mount", g.mount_points), ("dir", g.directions), ("faces", g.faces), ("tip", g.tip_radii),
            ("stroke", g.strokes), ("channels", g.probe_channels), ("scales", g.probe_scales),
            ("contact", g.nominal_contact_pose()), ("sigma", g.reading_sigma_mm))} | {"ids": list(g.probe_ids)})
    return out


#: what a recheck may change against its baseline calibration: its own settings and the warm-up
#: (sections), and in simulation the drift it injects (keys of ``[simulation]``; the seed stays)
_BASELINE_IGNORED = ("devices", "recheck", "warmup", "fleet")
_SIMULATED_DRIFT_KEYS = ("thermal_length_um", "thermal_offset_arcsec", "thermal_time_constant_s",
                         "step_joint", "step_offset_deg", "step_tool_um")


def baseline_fingerprint(config_toml: str, by_content: bool = False) -> dict[str, str]:
    """Section name → digest of a configuration text as a recheck compares it with its baseline:
    ``[devices]``, ``[recheck]`` and ``[warmup]`` left out, and the simulated drift keys of
    ``[simulation]`` (the robot moved; that is what a recheck is for). ``by_content``: the keys
    that name a file left out too (the caller compares the files' contents instead)."""
    try:
        data = tomllib.loads(config_toml) if config_toml else {}
    except tomllib.TOMLDecodeError:
        data = {}
    if by_content:
        data = without_file_paths(data)
    out = {}
    for k, v in data.items():
        if k in _BASELINE_IGNORED:
            continue
        if k == "simulation" and isinstance(v, dict):
            v = {kk: vv for kk, vv in v.items() if kk not in _SIMULATED_DRIFT_KEYS}
        out[f"[{k}]"] = _digest(v)
    return out


#: what only post-processes the measurements (the identification, the correction grid, tolerances,
#: the report's names, the tools' tables): a resume with only these changed reuses every measurement
POST_PROCESSING = ("[identification]", "[correction]", "[recheck]", "[tool]", "[cell]", "[verification]",
                   *(f"[{s}] {k}" for s, k in JUDGING_KEYS))


def post_processing_only(changed: Collection[str]) -> bool:
    """True when every changed key of a fingerprint only post-processes the measurements."""
    return all(k in POST_PROCESSING for k in changed)


def current_like(stored: dict[str, str], cfg: CellConfig) -> dict[str, str]:
    """``cfg``'s fingerprint made the way ``stored`` was (by content, or with paths before issue 37)."""
    return fingerprint(cfg, by_content=stored.get(BY_CONTENT[0]) == BY_CONTENT[1],
                       judged_apart=stored.get(JUDGED_APART[0]) == JUDGED_APART[1])


def check_same_cell(stored: dict[str, str], current: dict[str, str], run_id: int,
                    records: Iterable[Any] = ()) -> tuple[str, ...]:
    """Refuse (:class:`ConfigError`) to resume ``run_id`` on a cell whose fingerprint differs in
    what changes measurements (robot, set-up, head, body, plan, limits, simulation), naming what
    changed. Returns the post-processing sections that changed (``POST_PROCESSING``): the
    measurements stay valid and are reused, except verification readings (``records``: the run's
    measurements) made with the old identification or table, which refuse the resume."""
    changed = sorted(k for k in stored.keys() | current.keys()
                     if stored.get(k) != current.get(k) and k.strip("[]") not in _IGNORED)  # one stored before 39
    measuring = [k for k in changed if k not in POST_PROCESSING]
    if measuring:
        raise ConfigError(
            f"run {run_id} was measured on a different cell: {', '.join(changed)} changed since. Resuming would "
            f"mix data of two cells, so it was refused ({', '.join(POST_PROCESSING)} may change: they only "
            f"post-process the measurements). Restore the configuration the run started with "
            f"(its snapshot is in the run database), or start a new run (leave out --resume)")
    kinds = {str(getattr(r, "kind", "")) for r in records}
    for inputs, measured in _MEASURED_WITH:
        late = [k for k in changed if k in inputs]
        done = sorted(kinds & measured)
        if late and done:
            raise ConfigError(
                f"run {run_id}: {', '.join(late)} changed since, but its {', '.join(done)} poses were already "
                f"measured with the old {'table' if '[correction]' in late and len(late) == 1 else 'identification'}, "
                f"so they would not show the new one. Restore {', '.join(late)} to resume, or start a new run")
    return tuple(changed)


#: (sections, step kinds measured with them): the before poses are commanded through the identified
#: set-up, the after and oracle poses also through the uploaded table
_JUDGED = {f"[{s}] {k}" for s, k in JUDGING_KEYS}  # they change which poses the identification uses
_MEASURED_WITH = (({"[identification]", *_JUDGED}, {StepKind.VERIFY_BEFORE.value}),
                  ({"[identification]", "[correction]", *_JUDGED}, {StepKind.VERIFY_AFTER.value, StepKind.REFERENCE.value}))


def resume_note(changed: Collection[str]) -> str | None:
    """What a resume tells the operator when only post-processing sections changed."""
    if not changed:
        return None
    return (f"{', '.join(changed)} changed since the run was measured; they only post-process the "
            f"measurements, so every measurement on disk is reused and the results are computed anew")
