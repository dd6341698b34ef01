"""The configuration template ``station init`` writes: every table and key of the schema
(:mod:`station.cell.config.schema`) with its default, and each number's bounds in its comment
(a test checks that the comments state the schema's bounds). The ``[simulation]`` keys are
written from the schema itself (:func:`simulation_block`): they are many, and only a rehearsal
reads them, so they stay commented out with their defaults and bounds."""

from __future__ import annotations

import re
import textwrap
from typing import Any

import annotated_types

from station.cell.config.schema import _Simulation

_WIDTH = 110  # the template's longest comment lines

#: a shown value where the schema's default is "not given" (the seed then falls back to 1; a
#: set-up error is then drawn, so an example of the table is shown)
_SHOWN_DEFAULT: dict[str, Any] = {"seed": 1}


class _Form(str):
    """A shown value that is the form to write, not a value (``[ … ]``)."""


_SHOWN_DEFAULT["setup_error"] = _Form("{ z_mm = 1.5, yaw_deg = 0.3 }")
# absent means on where the simulator has the cell's files (the built-in cell has none: off)
_SHOWN_DEFAULT["collision_check"] = True


def _toml_value(v: Any) -> str:
    if isinstance(v, _Form):
        return str(v)
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (tuple, list)):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    if isinstance(v, float):
        return repr(v)
    if isinstance(v, str):  # a choice ("none", "six-axis"): a TOML string
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    return str(v)


def _bound(v: Any) -> str:
    return str(int(v)) if float(v).is_integer() else f"{v:g}"


def _bounds(info: Any) -> str:
    """``lo … hi`` as :func:`bounds_text` says it, with whole numbers written out (2**32 − 1)."""
    lo = hi = ""
    for m in info.metadata:
        if isinstance(m, annotated_types.Ge):
            lo = _bound(m.ge)
        elif isinstance(m, annotated_types.Gt):
            lo = f"> {_bound(m.gt)}"
        elif isinstance(m, annotated_types.Le):
            hi = _bound(m.le)
    return f"{lo} … {hi}" if lo and hi else ""


def _shown(key: str, info: Any) -> Any:
    """The value a commented key shows: its default; for a key without one ("not given: OTHER"),
    OTHER's default, which is what it then takes; else its lower bound."""
    if key in _SHOWN_DEFAULT:
        return _SHOWN_DEFAULT[key]
    if info.default is not None:
        return info.default
    if "list" in str(info.annotation):  # a list per joint, its length the robot's: its form only
        return _Form("[ … ]")
    m = re.search(r"not given: (\w+)", info.description or "")
    other = _Simulation.model_fields.get(m.group(1)) if m else None
    if other is not None and other.default is not None:
        return other.default
    lows = [getattr(x, "ge", None) for x in info.metadata if isinstance(x, annotated_types.Ge)]
    return lows[0] if lows else 0


def simulation_block() -> str:
    """The commented ``[simulation]`` keys: each with its default, its bounds and what it is, all
    taken from the schema (``_Simulation``), so the template cannot drift from it."""
    lines = []
    for key, info in _Simulation.model_fields.items():
        setting = f"# {key} = {_toml_value(_shown(key, info))}"
        rng = _bounds(info)
        what = f"{rng}: {info.description}" if rng else str(info.description)
        indent = f"{'#':<35}# "
        body = textwrap.wrap(what, width=_WIDTH - len(indent))
        if len(setting) > 34:  # a long shown value (an inline table): its comment starts below it
            lines.append(setting)
            body = [""] + body
        else:
            lines.append(f"{setting:<34} # {body[0]}")
        lines += [f"{indent}{more}" for more in body[1:]]
    return "\n".join(lines) + "\n"


TEMPLATE = """\
# Calibration cell configuration. Lengths in mm, angles in degrees, uncertainties in µm and
# arc seconds. 'station check THIS_FILE' connects to every device and reports what works.
# Every number has bounds, given as "lo … hi" in its comment; a value outside them, an unknown
# key or a wrong type is refused before anything moves, with the key and the fix.

[cell]
name = "cell 1"
# The report's traceability block names them (absent: "not recorded"):
# robot_serial = "SR800-0042"     # from the robot's plate
# controller = "RC700-A s/n 1234" # the controller's make, model and serial number
# operator = "J. Smith"           # 'calibrate --operator NAME' and 'report --operator NAME' name another

[robot]
model = "sr800"                  # built-in robot or a robot file (docs/robot-file.md)
# Nominal pose of the robot base in the calibration-body frame: x, y, z [mm], roll, pitch, yaw [deg]
# (positions within ±10000 mm, angles within ±360 deg).
# It only has to be right to a few mm / a few tenths of a degree; the calibration identifies it.
setup = [-450.0, 0.0, -170.0, 0.0, 0.0, 0.0]
setup_uncertainty_mm = 5.0       # how far a measuring point may lie from where setup puts it [mm], > 0 … 100:
                                 # the station locates the body within it (docs/station.md, "Locating the body")

[limits]
# Soft limits the station never commands a motion beyond: [lower, upper] per joint (deg | mm),
# finite, lower < upper, inside the robot file's limits.
joints = [[-125.0, 125.0], [-140.0, 140.0], [-195.0, -5.0], [-355.0, 355.0]]

[body]
cube_edge_mm = 40.0              # > 0 … 1000
# Measuring points (cube corners) from the body's CMM report: pose of each corner frame in the
# body frame, x, y, z [mm], roll, pitch, yaw [deg]. Corner frame: origin at the top corner, cube in x>=0, y>=0, z<=0.
# 3 … 5000 points; ids are unique, 1 … 64 characters. Either the CMM report as a CSV file,
# relative to this file (docs/data-files.md, "Calibration body"; columns id, x_mm, y_mm, z_mm,
# roll_deg, pitch_deg, yaw_deg, optionally sigma_position_um, sigma_angle_arcsec):
# file = "body.csv"
# or the points inline (a point may add sigma_position_um = 2.0, sigma_angle_arcsec = 5.0):
points = [
  { id = "C1.a", pose = [-28.3, -319.7, 40.0, 0.0, 0.0, 10.0] },
  { id = "C1.b", pose = [11.1, -312.8, 40.0, 0.0, 0.0, 100.0] },
  { id = "C1.c", pose = [4.1, -273.4, 40.0, 0.0, 0.0, 190.0] },
  { id = "C2.a", pose = [-228.3, -219.7, 140.0, 0.0, 0.0, 10.0] },
  { id = "C2.b", pose = [-188.9, -212.8, 140.0, 0.0, 0.0, 100.0] },
  { id = "C2.c", pose = [-195.9, -173.4, 140.0, 0.0, 0.0, 190.0] },
  { id = "C3.a", pose = [171.7, -219.7, 90.0, 0.0, 0.0, 10.0] },
  { id = "C3.b", pose = [211.1, -212.8, 90.0, 0.0, 0.0, 100.0] },
  { id = "C3.c", pose = [204.1, -173.4, 90.0, 0.0, 0.0, 190.0] },
]
# The CMM's uncertainty of a point that gives none; it goes into the identification's weights
# and σ (the measurements of one point share its error). 0: the body is taken as exact.
default_sigma_position_um = 0.0  # 0 … 1000
default_sigma_angle_arcsec = 0.0 # 0 … 3600

[devices]
probe_head = "/dev/ttyUSB0"      # serial device, or socket://host:port, rfc2217://host:port
probe_protocol = "keyence-dl-rs1a"  # the interface's dialect: "keyence-dl-rs1a", "mitutoyo-ga" or "station-ascii"
baudrate = 9600                  # as set on the unit; the DL-RS1A offers 2400 … 38400 (factory 9600)
probe_bytesize = 8               # data bits set on the unit: 7 or 8 (DL-RS1A factory 8)
probe_parity = "none"            # "none", "even" or "odd" (DL-RS1A factory none; 1 stop bit)
probe_timeout_s = 0.5            # 0.01 … 60
controller = "192.168.0.10:502"  # Modbus TCP host:port
device_id = 1                    # Modbus unit id, 0 … 255
word_order = "big"               # 32-bit word order of the controller: "big" or "little"
controller_timeout_s = 1.0       # 0.01 … 60
controller_link_timeout_s = 1.0  # the robot program's heartbeat may stand still this long [s], 0.2 … 60
motion_timeout_s = 60.0          # longest single motion [s], 1 … 600
controller_register_base = 0     # first register of the robot program's 128-register window, 0 … 65407 (UR: 128)

[plan]
elbows = [1, -1]                 # elbow configurations to measure every point in: [1, -1] or [1]
approach_deg = 0.5               # every joint approaches its target from below by this much, > 0 … 10
approach_mm = 1.0                # > 0 … 50
clearance_mm = 20.0              # retract height above a measuring point before moving on, > 0 … 500
speed = 0.5                      # fraction of the robot's maximum speed, > 0 … 1
settle_s = 0.2                   # wait after a motion before reading the probes [s], 0 … 30
samples = 4                      # probe snapshots averaged per reading, 1 … 100
max_spread_um = 10.0             # reject a reading whose snapshots spread more than this, > 0 … 1000
both_directions = false          # also approach from above to measure the reversal error; needed for
#                                # [identification] model = "...backlash" (auto then tries it too)
verification_every = 4           # every 4th (point, elbow) is held out for verification, 2 … 100
verification_cycles = 3          # ISO 9283 repetitions per verification pose, 1 … 30
select = 0                       # > 0: keep only this many most informative steps (D-optimal), 0 … 5000
repeats = 2                      # visits per identification pose (robot repeatability averages out), 1 … 20
recenter_attempts = 2            # re-centre when a probe is near the end of its stroke, 0 … 10
recenter_margin_mm = 1.5         # 0 … 4, less than half the probes' stroke (the built-in head's: ±5 mm;
#                                # a [head] file states its own)
max_residual_um = 10.0           # plane residual above which a reading is not valid, > 0 … 1000
remeasure_attempts = 1           # re-touches when a redundant head's probes disagree, 0 … 5
locate_steps = 3                 # search steps per face normal when locating the body, 0 … 20
collision_margin_mm = 2.0        # least clearance of every pose and path [mm], > 0 … 200 (docs/collision.md)

# [head]
# file = "head.toml"             # the probe-head file (docs/probe-head.md), relative to this file;
#                                # without it: the built-in reference 3-2-1 head (examples/heads/reference-321.toml)

[identification]
objective = "pose"               # "pose" (robot + set-up + head) or "distance" (robot only)
sigma_position_um = 15.0         # 0.01 … 1000
sigma_angle_arcsec = 20.0        # 0.01 … 3600
# prefer = ["K.x", ...]          # minimal-set preferences; default: the robot file's
# fix = []
# exclude = []
model = "geometric"              # error terms beyond geometry (docs/error-terms.md): "geometric", "auto"
#                                # (kept where cross-validation says so) or terms such as "compliance+cyclic";
#                                # objective = "pose" only; a SCARA's table carries them (its vertical
#                                # axes take no compliance: "cyclic" or "auto")

[correction]
# The correction table's grid describes the head frame's origin (MKKS, the point the head's CMM
# report names; the built-in head's is about 60 mm above the corner it touches) in the robot base
# frame, and its yaw. The station designs it: the region around every verification target (with
# a margin for the set-up guess and a re-centred touch) and one step per axis, so that robots
# with errors of the size the simulation table's *_sigma_* keys state meet the bound within the
# controller's 32 000 values. 'station plan' shows the design, its value count and its predicted bound
# (docs/correction.md, "The table's design").
max_interpolation_um = 15.0      # refuse a table whose interpolation bound exceeds this, > 0 … 1000
# region = { x_mm = [300.0, 650.0], y_mm = [-350.0, 350.0], z_mm = [250.0, 400.0] }
#                                # the TCP's working box instead of the derived one [low, high] mm
# Or the grid itself, all three: [start, stop, step] mm, stop > start, a whole number of steps,
# step 1 … 10000; checked the same way before any motion:
# x_mm = [250.0, 650.0, 40.0]
# y_mm = [-350.0, 350.0, 50.0]
# z_mm = [250.0, 450.0, 200.0]
# yaw_step_deg = 30.0            # 1 … 180, a divisor of 360 (designed when absent)

[verification]
# The accuracy specification the report judges the held-out poses against after correction (ISO
# 9283: AP, pose accuracy, and RP, pose repeatability, per pose), and the test conditions it
# states. Absent: not judged / not recorded. The run's outcome stays the improvement ratio's.
# max_ap_um = 50.0               # largest AP accepted per pose [µm], > 0 … 10000
# max_rp_um = 30.0               # largest RP accepted per pose [µm], > 0 … 10000
# temperature_c = 20.0           # the cell's air temperature during the test [°C], -40 … 80
# load_kg = 2.5                  # mass on the flange: probe head and adapter [kg], 0 … 2000

[recheck]
# 'station recheck': a short check of a few poses against the last calibration (the baseline).
# A tolerance of 0 is derived from the baseline's own accuracy.
poses = 10                       # poses measured (plus one repeat of the first), 3 … 100
tolerance_um = 0.0               # RMS position drift accepted [µm]; 0: 3× the baseline's accuracy, 0 … 10000
offset_tolerance_arcsec = 0.0    # joint offset change accepted [″]; 0: tolerance_um over 500 mm, 0 … 36000
length_tolerance_um = 0.0        # arm length change accepted [µm]; 0: tolerance_um, 0 … 10000
repeat_tolerance_um = 0.0        # first pose vs its repeat [µm], else untrusted; 0: tolerance_um, 0 … 10000
# interval_days = 0              # days between rechecks (the fleet's due dates); 0: [fleet]'s, 0 … 3650

[fleet]
# The plant's fleet store (docs/fleet.md): each finished run is published there, or queued in the
# run database and sent later by 'station sync'. No credentials here: ~/.pgpass, the libpq
# service file or PG* variables hold them. STATION_FLEET_URL overrides url.
# url = "postgresql://fleet.plant.example/fleet"  # or "service=plant"
# station = "cart-1"             # this station's name in the fleet (default: the host name)
recheck_interval_days = 30       # days between rechecks where [recheck] has none, 1 … 3650

[warmup]
# Before 'calibrate' and 'recheck': cycles of a motion program over the workspace, each ended by
# a measurement of one reference pose, until the pose stops moving or for a set time.
enabled = false
until = "converged"              # "converged" or "time"
minutes = 20.0                   # longest warm-up (until = "time": its length) [min], > 0 … 600
max_cycles = 200                 # 1 … 100000
converged_um = 2.0               # remaining drift of the reference pose (extrapolated) [µm], > 0 … 1000
program_poses = 8                # poses of the motion program per cycle, 2 … 100

[conformance]
# 'station conformance': checks the robot program against the register map and handshake
# (docs/robot-program.md). Park the robot at park_joints first; the kit moves it only inside the
# park zone, park_joints ± test_move per joint. With one joint parked within test_move of its
# soft limit (here the quill near its top) the kit also checks that an out-of-limits target is
# refused, with a target that stays inside the park zone.
# park_joints = [0.0, 90.0, -6.0, 0.0]  # deg | mm, one per joint, inside [limits]: required for it
test_move = 2.0                  # half-width of the park zone (deg | mm), 0.1 … 5
move_speed = 0.05                # speed of the test motions, fraction of the maximum, 0.001 … 0.2
position_tolerance = 0.01        # arrived joints vs target (deg | mm), 0.0001 … 1

# Tools that replace the probe head after the calibration, at most 16, one [[tool]] table each:
# the station builds each tool's own correction from the identified model (docs/correction.md,
# "Tools after the head"); 'station export --tool NAME' writes its table for the controller.
# [[tool]]
# name = "gripper"               # unique; letters, digits, _ . -, 1 … 64 characters
# tcp = [50.0, 0.0, -200.0, 0.0, 0.0, 0.0]  # TCP in the flange frame from the tool's measurement:
#                                # x, y, z [mm] within ±2000, roll, pitch, yaw [deg] within ±360
# z_mm = [150.0, 350.0, 200.0]   # optional x_mm, y_mm, z_mm: the tool's own grid (default: [correction])

# The cell's fixed obstacles, at most 64, one [[obstacle]] table each (docs/collision.md):
# [[obstacle]]
# name = "column"                # names it in a refusal
# shape = "cylinder"             # "box" (size_mm = [x, y, z]) or "cylinder" (radius_mm, height_mm; axis along z)
# frame = "body"                 # "body" (the body frame) or "base" (the robot's base frame)
# pose = [400.0, 0.0, 500.0, 0.0, 0.0, 0.0]  # its centre: x, y, z [mm], roll, pitch, yaw [deg]
# radius_mm = 60.0
# height_mm = 1000.0

[simulation]
# Read only by a rehearsal, 'station calibrate --simulated THIS_FILE' (this cell against
# simulators) and 'python -m simulators --config THIS_FILE'; a real run ignores it. Each key is
# optional; shown with its default, what it is and its bounds:
""" + simulation_block()
