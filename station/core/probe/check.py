"""Checks of a probe head: does its arrangement fix the cube corner, how precisely, and does a
redundant head's touch hold together (pure numerics, no I/O).

Arrangement (at load time, :func:`check_arrangement`)
-----------------------------------------------------
The contact Jacobian ``G = ds/dpose (n,6)`` at the nominal touch maps a small pose change of the
corner (x, y, z [mm], roll, pitch, yaw [rad]) to the probe readings. Its rotation columns are
scaled by the cube edge (rad·edge is mm of motion at the far end of a face), so its singular
values compare. Rank < 6 means a motion of the corner that no probe sees: it is named from the
null space (``"x translation and yaw"``), with the probes whose readings depend on each other
(the left null space) and the faces where one more probe would fix it. A condition number above
:data:`MAX_CONDITION` is refused as well (1 µm of reading error would become millimetres).

Sensitivity (:func:`sensitivity`): ``σ_pose = sqrt(diag((GᵀG)⁻¹))·σ_reading`` at the nominal
touch (:func:`station.core.probe.geometry.contact_pose_covariance`), per 1 µm of reading σ:
position [µm] and angle [″].

Redundancy (more than six probes)
---------------------------------
* :func:`residual_test`: the reading residuals ``e = s - s(M̂)`` of the least-squares pose,
  ``χ² = Σ (e_i/σ)²`` with ``n - 6`` degrees of freedom against its ``1 - alpha`` quantile
  (``σ``: the head's ``reading_sigma_mm``), and the studentised residuals
  ``t_i = e_i / (σ sqrt(1 - h_ii))`` (``h``: the hat matrix of ``G``).
* :func:`leave_one_out`: the probes whose removal leaves an arrangement that still fixes the
  pose and then passes the test. One such probe with a redundant rest is named. With seven
  probes every removal leaves six, which fit exactly: a bad touch is detected, but a constant
  offset on one probe cannot be singled out from one touch (every probe explains it equally);
  :func:`isolable_probes` says which probes of an arrangement can be singled out.
* :func:`frozen_probes`: a stuck probe repeats its reading while the pose solved from the other
  probes says it should have moved. This singles a stuck probe out even on a seven-probe head.
"""

from __future__ import annotations

from dataclasses import dataclass
from types import SimpleNamespace

import numpy as np

from station.core.kinematics.transforms import pose_to_matrix
from station.core.probe.geometry import (
    _MIN_INCIDENCE,
    FACE_NORMALS,
    PoseSolution,
    PoseSolveError,
    ProbeHeadGeometry,
    _contact,
    contact_pose_covariance,
    readings_from_pose,
    solve_pose,
)
from station.core.units import ARCSEC
from station.errors import ConfigError

__all__ = [
    "MAX_CONDITION",
    "FACE_NAMES",
    "ArrangementReport",
    "ResidualTest",
    "LeaveOneOut",
    "contact_jacobian",
    "check_arrangement",
    "check_head",
    "sensitivity",
    "residual_test",
    "leave_one_out",
    "isolable_probes",
    "frozen_probes",
    "solve_without",
    "Diagnosis",
    "diagnose",
]

#: an arrangement whose scaled contact Jacobian is worse conditioned than this is refused
MAX_CONDITION = 1000.0
#: relative singular value below which a motion counts as not fixed
_RANK_TOL = 1e-6
FACE_NAMES = ("top", "x", "y")
_MOTIONS = ("x translation", "y translation", "z translation", "roll", "pitch", "yaw")
#: default false-alarm probability of the residual test per touch
ALPHA = 1e-3


@dataclass(frozen=True, eq=False)
class ArrangementReport:
    """``rank`` and ``condition`` of the scaled contact Jacobian at the nominal touch;
    ``sigma_position_um (3,)`` and ``sigma_angle_arcsec (3,)``: pose σ per 1 µm reading σ;
    ``redundancy``: n - 6; ``isolable``: labels of the probes a bad touch can be pinned on from
    one touch (empty for six or seven probes); ``unchecked``: probes of a redundant head whose
    reading no other probe checks (a fault there cannot be detected)."""

    n_probes: int
    rank: int
    condition: float
    sigma_position_um: np.ndarray
    sigma_angle_arcsec: np.ndarray
    redundancy: int
    isolable: tuple[str, ...]
    unchecked: tuple[str, ...] = ()

    def lines(self) -> list[str]:
        """What ``station validate`` / ``station plan`` print about the head."""
        p, a = self.sigma_position_um, self.sigma_angle_arcsec
        out = [f"probe head: {self.n_probes} probes, rank {self.rank} of 6, condition {self.condition:.1f}",
               f"  1 µm reading error -> position σ x {p[0]:.2f}, y {p[1]:.2f}, z {p[2]:.2f} µm; "
               f"angle σ roll {a[0]:.1f}, pitch {a[1]:.1f}, yaw {a[2]:.1f} ″"]
        if self.redundancy == 0:
            out.append("  six probes: the pose is exact, a bad touch cannot be detected")
        else:
            single = (f"a bad probe can be named from one touch: {', '.join(self.isolable)}" if self.isolable
                      else "a bad touch is detected; a stuck probe (repeated reading) or a dead channel "
                           "is named, an offset on one probe is not")
            out.append(f"  {self.redundancy} redundant reading(s): {single}")
            if self.unchecked:
                out.append(f"  no other probe checks {', '.join(self.unchecked)}: a fault there goes undetected; "
                           f"add a probe that measures the same motion")
        return out

    def to_json(self) -> dict:
        return {"n_probes": self.n_probes, "rank": self.rank, "condition": self.condition,
                "sigma_position_um_per_um": [float(v) for v in self.sigma_position_um],
                "sigma_angle_arcsec_per_um": [float(v) for v in self.sigma_angle_arcsec],
                "redundancy": self.redundancy, "isolable": list(self.isolable), "unchecked": list(self.unchecked)}


def _rows(points: np.ndarray, directions: np.ndarray, faces: np.ndarray, tip_radii: np.ndarray,
          M: np.ndarray) -> np.ndarray:
    """``(n,6)`` derivative of the unclipped readings w.r.t. the pose vector at ``M``, for any
    number of probes (a :class:`ProbeHeadGeometry` needs six)."""
    from station.core.kinematics.transforms import matrix_to_pose

    d = np.asarray(directions, dtype=float)
    g = SimpleNamespace(mount_points=np.asarray(points, dtype=float),
                        directions=d / np.linalg.norm(d, axis=1, keepdims=True),
                        faces=np.asarray(faces, dtype=int),
                        tip_radii=np.broadcast_to(np.asarray(tip_radii, dtype=float), (len(d),)))
    p0 = matrix_to_pose(np.asarray(M, dtype=float))
    h = 1e-6
    s, _, _ = _contact(g, pose_to_matrix(p0 + np.concatenate([np.eye(6) * h, -np.eye(6) * h])))  # type: ignore[arg-type]
    # a probe parallel to its face has infinite readings: its row is NaN, which the callers
    # treat as "this probe fixes nothing" (check_arrangement names it)
    with np.errstate(invalid="ignore"):
        return np.asarray(((s[:6] - s[6:]) / (2 * h)).T)


def _blind(directions: np.ndarray, faces: np.ndarray, nominal_pose: np.ndarray, G: np.ndarray) -> np.ndarray:
    """``(n,)`` bool: probes that do not point into their face at the nominal touch (the
    geometry's own test, :data:`~station.core.probe.geometry._MIN_INCIDENCE`) or whose row of
    the contact Jacobian is not finite: they fix no motion of the corner."""
    d = np.asarray(directions, dtype=float)
    d = d / np.linalg.norm(d, axis=1, keepdims=True)
    normals = FACE_NORMALS[faces] @ np.asarray(nominal_pose, dtype=float)[:3, :3].T   # (n,3) in MKKS
    incidence = np.einsum("ni,ni->n", normals, d)
    return ~(incidence < -_MIN_INCIDENCE) | ~np.all(np.isfinite(G), axis=1)


def contact_jacobian(geom: ProbeHeadGeometry, M: np.ndarray | None = None) -> np.ndarray:
    """``(n,6)`` d reading / d pose at ``M`` (default: the nominal touch), rotation columns in
    mm per rad (unscaled)."""
    M = geom.nominal_contact_pose() if M is None else M
    return _rows(geom.mount_points, geom.directions, geom.faces, geom.tip_radii, M)


def _join(words: list[str]) -> str:
    return words[0] if len(words) == 1 else ", ".join(words[:-1]) + " and " + words[-1]


def check_arrangement(points, directions, faces, tip_radii, nominal_pose: np.ndarray,
                      cube_edge_mm: float, labels: list[str] | tuple[str, ...]) -> tuple[int, float]:
    """Rank and condition of the scaled contact Jacobian at the nominal touch; raises
    :class:`ConfigError` naming the motion no probe fixes, the probes involved and the fix.
    Works for any number of probes (five give the missing motion, not just "too few")."""
    faces = np.asarray(faces, dtype=int)
    G = _rows(points, directions, faces, tip_radii, nominal_pose)
    n = G.shape[0]
    blind = _blind(directions, faces, nominal_pose, G)
    # a probe parallel to its face has a NaN row, which would stop the SVD: it fixes nothing.
    # (A probe pointing away keeps its row; the geometry names it when the rank is full.)
    G = np.where(np.all(np.isfinite(G), axis=1)[:, None], G, 0.0)
    scale = np.r_[np.ones(3), np.full(3, 1.0 / cube_edge_mm)]
    Gs = G * scale
    U, sv, Vt = np.linalg.svd(Gs, full_matrices=True)
    sv6 = np.zeros(6)
    sv6[: len(sv)] = sv
    top = max(sv6[0], 1e-300)
    rank = int(np.sum(sv6 > _RANK_TOL * top))
    condition = float(sv6[0] / sv6[5]) if sv6[5] > 0 else float("inf")
    if rank < 6:
        null = Vt[rank:].T                                    # (6, 6-rank) unfixed motions
        weight = np.sum(null**2, axis=1)                      # how much each motion is free
        free = [_MOTIONS[k] for k in range(6) if weight[k] > 0.05]
        # probes whose readings depend on each other (the left null space of G)
        dependent = U[:, rank:] if U.shape[1] > rank else np.zeros((n, 0))
        inv = [labels[i] for i in range(n)
               if not blind[i] and dependent.size and np.sum(dependent[i] ** 2) > 1e-6]
        # faces where one more probe (pointing straight in, at a few points of the face) fixes more
        helps = []
        for f in range(3):
            cand = _face_candidates(f, cube_edge_mm)
            for c in cand:
                pt = (nominal_pose[:3, :3] @ (c + FACE_NORMALS[f] * 1.0)) + nominal_pose[:3, 3]
                row = _rows(pt[None], -(nominal_pose[:3, :3] @ FACE_NORMALS[f])[None], np.array([f]),
                            np.array([1.0]), nominal_pose)
                rows = np.vstack([G, row]) * scale
                s2 = np.linalg.svd(rows, compute_uv=False)
                if np.sum(s2 > _RANK_TOL * max(s2[0], 1e-300)) > rank:
                    helps.append(FACE_NAMES[f])
                    break
        faces_hint = "a probe on " + (" or ".join(f"the {h} face" for h in helps) if helps else "another face") + ","
        # each face's plane is seen only along its normal: a face without a probe that points
        # into it leaves that translation free whatever the other faces hold
        bare = [FACE_NAMES[f] for f in range(3) if not np.any((faces == f) & ~blind)]
        if bare:
            faces_hint = (f"{'probes' if len(bare) > 1 else 'a probe'} on {_join([f'the {b} face' for b in bare])} "
                          "(every face needs at least one probe pointing into it),")
        who = (f"probes {', '.join(inv)} measure dependent motions (same face and in line, or parallel)"
               if inv else f"{n - int(blind.sum())} probe(s) cannot fix six degrees of freedom")
        if blind.any():
            who += (f"; probes {', '.join(labels[i] for i in range(n) if blind[i])} do not point into their "
                    "face and fix nothing (check their direction and face)")
        by_face = "; ".join(f"{FACE_NAMES[f]} face: {', '.join(labels[i] for i in range(n) if faces[i] == f) or 'none'}"
                            for f in range(3))
        raise ConfigError(
            f"the probe arrangement does not fix {_join(free) if free else 'the pose'} of the cube corner "
            f"(contact Jacobian rank {rank} of 6): {who} ({by_face}); add {faces_hint} "
            f"or move the probes involved apart")
    if condition > MAX_CONDITION:
        weak = _MOTIONS[int(np.argmax(np.abs(Vt[5])))]
        raise ConfigError(
            f"the probe arrangement fixes the pose only weakly (condition {condition:.0f} > {MAX_CONDITION:.0f}, "
            f"weakest: {weak}): move the probes on the faces that see {weak} farther apart")
    return rank, condition


def _face_candidates(face: int, E: float) -> list[np.ndarray]:
    """A few contact points (MPKS) on a face, well inside it."""
    a, b = 0.25 * E, 0.75 * E
    if face == 0:
        return [np.array([x, y, 0.0]) for x, y in ((a, a), (b, a), (a, b))]
    if face == 1:
        return [np.array([0.0, y, z]) for y, z in ((a, -a), (b, -a), (a, -b))]
    return [np.array([x, 0.0, z]) for x, z in ((a, -a), (b, -a), (a, -b))]


def sensitivity(geom: ProbeHeadGeometry, sigma_mm: float = 0.001) -> tuple[np.ndarray, np.ndarray]:
    """Pose σ at the nominal touch for a reading σ of ``sigma_mm`` on every probe: position
    ``(3,)`` [µm] and angle ``(3,)`` [arc seconds] (roll, pitch, yaw)."""
    cov = contact_pose_covariance(geom, geom.nominal_contact_pose(), sigma_mm)
    sd = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    return sd[:3] * 1000.0, sd[3:] / ARCSEC


def check_head(geom: ProbeHeadGeometry) -> ArrangementReport:
    """The load-time check of a built geometry: rank, condition, sensitivity, isolability."""
    labels = [geom.label(i) for i in range(geom.n_probes)]
    rank, condition = check_arrangement(geom.mount_points, geom.directions, geom.faces, geom.tip_radii,
                                        geom.nominal_contact_pose(), geom.cube_edge_mm, labels)
    pos, ang = sensitivity(geom)
    iso = isolable_probes(geom)
    unchecked: tuple[str, ...] = ()
    if geom.n_probes > 6:
        free = 1.0 - _hat_diag(contact_jacobian(geom))
        unchecked = tuple(labels[i] for i in range(geom.n_probes) if free[i] < 1e-3)
    return ArrangementReport(geom.n_probes, rank, condition, pos, ang, geom.n_probes - 6,
                             tuple(labels[i] for i in iso), unchecked)


# --------------------------------------------------------------------------------------------
# redundancy: the residual test and the probe that disagrees
# --------------------------------------------------------------------------------------------

@dataclass(frozen=True, eq=False)
class ResidualTest:
    """``residuals_mm (n,)`` reading residuals; ``studentised (n,)`` (NaN where a probe's
    reading is fixed by the others alone: it cannot be checked); ``chi2`` against
    ``threshold`` (the ``1 - alpha`` quantile with ``dof = n - 6``)."""

    residuals_mm: np.ndarray
    studentised: np.ndarray
    chi2: float
    dof: int
    threshold: float
    passed: bool

    @property
    def rms_um(self) -> float:
        return float(np.sqrt(np.mean(self.residuals_mm**2)) * 1e3)


def _hat_diag(G: np.ndarray) -> np.ndarray:
    Q, _ = np.linalg.qr(G)
    return np.asarray(np.sum(Q**2, axis=1))


def residual_test(geom: ProbeHeadGeometry, readings: np.ndarray, M: np.ndarray,
                  alpha: float = ALPHA, sigma_mm: float | None = None) -> ResidualTest:
    """χ² test of the readings ``(n,)`` against the pose ``M`` solved from them."""
    from scipy.stats import chi2  # scipy.stats nearly doubles start-up: loaded only where a test runs

    sigma = geom.reading_sigma_mm if sigma_mm is None else float(sigma_mm)
    s_pred, _, incidence = _contact(geom, np.asarray(M, dtype=float))
    e = np.asarray(readings, dtype=float) - s_pred
    n = geom.n_probes
    dof = n - 6
    # the solver fits plane residuals (reading x incidence): its hat matrix has those rows
    G = contact_jacobian(geom, M) * np.abs(incidence)[:, None]
    one_minus_h = 1.0 - _hat_diag(G)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(one_minus_h > 1e-9, e / (sigma * np.sqrt(np.clip(one_minus_h, 1e-300, None))), np.nan)
    c2 = float(np.sum((e / sigma) ** 2))
    thr = float(chi2.ppf(1.0 - alpha, dof)) if dof > 0 else 0.0
    e.flags.writeable = False
    t.flags.writeable = False
    return ResidualTest(e, t, c2, dof, thr, bool(dof == 0 or c2 <= thr))


@dataclass(frozen=True, eq=False)
class LeaveOneOut:
    """``candidates``: the probes whose removal leaves an arrangement that fixes the pose and
    passes the test; ``verified``: the same, where the rest still has a redundant reading (its
    passing means something). ``solutions``: probe -> pose solved without it."""

    candidates: tuple[int, ...]
    verified: tuple[int, ...]
    solutions: dict[int, PoseSolution]
    tests: dict[int, ResidualTest]

    @property
    def named(self) -> int | None:
        """The one probe that disagrees, when the rest singles it out."""
        return self.verified[0] if len(self.verified) == 1 else None


def fixes_pose(geom: ProbeHeadGeometry) -> bool:
    try:
        check_arrangement(geom.mount_points, geom.directions, geom.faces, geom.tip_radii,
                          geom.nominal_contact_pose(), geom.cube_edge_mm, list(geom.probe_ids))
    except ConfigError:
        return False
    return True


def solve_without(geom: ProbeHeadGeometry, readings: np.ndarray, k: int,
                  alpha: float = ALPHA) -> tuple[PoseSolution, ResidualTest] | None:
    """Pose from every probe but ``k`` and its residual test, or None when the rest cannot fix
    the pose or give no solution."""
    keep = np.arange(geom.n_probes) != k
    if geom.n_probes - 1 < 6:
        return None
    sub = geom.subset(keep)
    if not fixes_pose(sub):
        return None
    r = np.asarray(readings, dtype=float)[keep]
    try:
        sol = solve_pose(sub, r, check_residuals=False)
    except PoseSolveError:
        return None
    return sol, residual_test(sub, r, sol.M, alpha)


def leave_one_out(geom: ProbeHeadGeometry, readings: np.ndarray, alpha: float = ALPHA) -> LeaveOneOut:
    """Which single probe, left out, makes the touch consistent (see :class:`LeaveOneOut`). The
    rest is tested at ``alpha / 10``: once the touch failed, the question is which explanation
    fits, and a rest that is merely unlucky must not hide the bad probe."""
    alpha = alpha / 10
    cands, verified = [], []
    sols: dict[int, PoseSolution] = {}
    tests: dict[int, ResidualTest] = {}
    for k in range(geom.n_probes):
        got = solve_without(geom, readings, k, alpha)
        if got is None:
            continue
        sols[k], tests[k] = got
        if got[1].passed:
            cands.append(k)
            if got[1].dof > 0:
                verified.append(k)
    return LeaveOneOut(tuple(cands), tuple(verified), sols, tests)


def isolable_probes(geom: ProbeHeadGeometry, ratio: float = 0.2) -> tuple[int, ...]:
    """Probes on which a bad reading can be pinned from one touch: a fault on probe ``k`` leaves
    a residual in the rest whenever any other probe ``j`` is left out (linear analysis at the
    nominal touch: the residual of the rest without ``j`` keeps at least ``ratio`` of the
    fault's residual in the whole head)."""
    n = geom.n_probes
    if n < 8:
        return ()
    G = contact_jacobian(geom)

    def proj(rows: np.ndarray) -> np.ndarray:
        Q, _ = np.linalg.qr(G[rows])
        return np.eye(len(rows)) - Q @ Q.T

    P_all = proj(np.arange(n))
    out = []
    for k in range(n):
        full = np.linalg.norm(P_all[:, k])
        if full < 1e-6:
            continue
        ok = True
        for j in range(n):
            if j == k:
                continue
            rows = np.array([i for i in range(n) if i != j])
            if np.linalg.matrix_rank(G[rows] * np.r_[np.ones(3), np.full(3, 1 / geom.cube_edge_mm)], tol=1e-6) < 6:
                continue  # without j the rest cannot fix the pose: j is never a candidate
            e = np.zeros(n - 1)
            e[list(rows).index(k)] = 1.0
            if np.linalg.norm(proj(rows) @ e) < ratio * full:
                ok = False
                break
        if ok:
            out.append(k)
    return tuple(out)


def frozen_probes(geom: ProbeHeadGeometry, readings: np.ndarray, previous: list[np.ndarray],
                  candidates: tuple[int, ...], alpha: float = ALPHA) -> dict[int, float]:
    """Candidates that repeat their reading while the head moved: probe -> the change [mm] the
    other probes predict for it. ``previous``: the readings ``(n,)`` of the touches before this
    one, most recent first.

    A probe counts as frozen when it kept its reading (within 4 σ) over the most recent touches
    (its *frozen stretch*) and, over that stretch, at least once both the pose solved from the
    other probes moved it by more than 20 σ and the other probes' readings changed by more than
    20 σ (their median change: robust to one bad probe among them). The second condition keeps
    a healthy probe that was merely touched at the same place twice from being called frozen on
    the strength of a pose that the really stuck probe corrupts."""
    sigma = geom.reading_sigma_mm
    r = np.asarray(readings, dtype=float)
    out: dict[int, float] = {}
    for k in candidates:
        now = solve_without(geom, r, k, alpha)
        if now is None:
            continue
        keep = np.arange(geom.n_probes) != k
        pred_now = readings_from_pose(geom, now[0].M)[k]
        evidence = 0.0
        for prev in previous:
            p = np.asarray(prev, dtype=float)
            if p.shape != r.shape or not np.isfinite(p[k]) or abs(r[k] - p[k]) > 4 * sigma:
                break  # the probe moved since that touch: the frozen stretch ends here
            if not np.all(np.isfinite(p[keep])):
                continue
            moved = float(np.median(np.abs(r[keep] - p[keep])))
            then = solve_without(geom, p, k, alpha)
            if then is None or moved <= 20 * sigma:
                continue
            pred_then = readings_from_pose(geom, then[0].M)[k]
            if np.isfinite(pred_now) and np.isfinite(pred_then):
                evidence = max(evidence, abs(pred_now - pred_then))
        if evidence > 20 * sigma:
            out[k] = float(evidence)
    return out


@dataclass(frozen=True, eq=False)
class Diagnosis:
    """Why a redundant touch failed its residual test. ``suspect``: the one probe it is pinned
    on (None: not possible); ``solution`` / ``test``: the pose and its test without the suspect;
    ``candidates``: the probes any one of which could explain it; ``reason``: for people;
    ``stuck``: the suspect repeats its reading while the other probes show the head moving (a
    stuck probe, not an offset: it stays wrong at every later touch)."""

    suspect: int | None
    candidates: tuple[int, ...]
    solution: PoseSolution | None
    test: ResidualTest | None
    reason: str
    stuck: bool = False


def diagnose(geom: ProbeHeadGeometry, readings: np.ndarray, full: ResidualTest,
             previous: list[np.ndarray] | None = None, alpha: float = ALPHA) -> Diagnosis:
    """Pin a failed residual test ``full`` on one probe: by leave-one-out where the rest stays
    redundant, else by a repeated (frozen) reading over ``previous`` touches (most recent first,
    ``(n,)`` each in probe order)."""
    r = np.asarray(readings, dtype=float)
    loo = leave_one_out(geom, r, alpha)
    n = geom.n_probes
    # "probes disagree" first and alone before the colon: the runner's failure cause
    head = (f"probes disagree: χ² {full.chi2:.1f} > {full.threshold:.1f} ({full.dof} redundant), residual RMS "
            f"{full.rms_um:.1f} µm at σ {geom.reading_sigma_mm * 1e3:g} µm")
    k = loo.named
    if k is not None:
        # eight or more probes single a bad probe out from one touch; a repeated reading says
        # whether it is stuck (it stays wrong) rather than off by debris
        frozen = frozen_probes(geom, r, list(previous or []), (k,), alpha) if previous else {}
        if k in frozen:
            return Diagnosis(k, loo.candidates, loo.solutions[k], loo.tests[k],
                             f"{head}: probe {geom.label(k)} stuck? it repeats its reading {r[k]:.4f} mm while "
                             f"the other probes moved it by {frozen[k] * 1e3:.0f} µm since an earlier touch", True)
        t = full.studentised[k]
        return Diagnosis(k, loo.candidates, loo.solutions[k], loo.tests[k],
                         f"{head}: probe {geom.label(k)} is off by {full.residuals_mm[k] * 1e3:+.1f} µm "
                         f"(studentised {t:+.1f}), the other {n - 1} probes agree")
    frozen = frozen_probes(geom, r, list(previous or []), loo.candidates, alpha) if loo.candidates else {}
    ranked = sorted(frozen.items(), key=lambda kv: -kv[1])
    # one frozen probe, or one whose evidence dominates: a healthy probe that the motion happened
    # not to move looks frozen too, but the pose the stuck probe corrupts predicts it far less
    if ranked and (len(ranked) == 1 or ranked[0][1] >= 3.0 * ranked[1][1]):
        k, moved = ranked[0]
        return Diagnosis(k, loo.candidates, loo.solutions[k], loo.tests[k],
                         f"{head}: probe {geom.label(k)} stuck? it repeats its reading {r[k]:.4f} mm while the "
                         f"other probes moved it by {moved * 1e3:.0f} µm since an earlier touch", True)
    if loo.candidates:
        names = ", ".join(geom.label(i) for i in loo.candidates)
        why = (f"any one of {names} could be the bad probe ({n} probes detect a bad touch but cannot "
               f"single out an offset on one probe)" if len(loo.candidates) > 1 else f"probe {names} could be it")
        return Diagnosis(None, loo.candidates, None, None, f"{head}: {why}; clean the probe tips and the cube")
    return Diagnosis(None, (), None, None, f"{head}: no single probe explains it (several bad probes, or a "
                                           "probe touched another surface); clean and check the probes")
