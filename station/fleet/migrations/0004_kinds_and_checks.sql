-- Issue 39: every figure with its kind, and no row a station's role can write that breaks a reader.
--
-- A simulated run (a rehearsal on the simulator) is marked: it never makes a robot "ok". The
-- operator who ran it is a column of its own (QA filters by it). Existing rows were published
-- before the mark existed: they stay unmarked (false), as they were shown.
ALTER TABLE runs ADD COLUMN simulated BOOLEAN NOT NULL DEFAULT false;
ALTER TABLE runs ADD COLUMN operator TEXT;

-- Impossible values are refused on the way in. NOT VALID: the rows already stored are not
-- re-checked (a migration never fails on, or deletes, what a plant holds); the readers show such a
-- row as damaged instead of failing (station/fleet/overview.py).
ALTER TABLE runs ADD CONSTRAINT runs_started_plausible
    CHECK (started_utc >= '2000-01-01 00:00:00+00' AND started_utc < '2200-01-01 00:00:00+00') NOT VALID;
ALTER TABLE runs ADD CONSTRAINT runs_finished_plausible
    CHECK (finished_utc >= '2000-01-01 00:00:00+00' AND finished_utc < '2200-01-01 00:00:00+00') NOT VALID;
ALTER TABLE runs ADD CONSTRAINT runs_interval_plausible
    CHECK (recheck_interval_days IS NULL OR recheck_interval_days BETWEEN 1 AND 3650) NOT VALID;
-- figures are finite and not negative: NaN compares above every number in PostgreSQL, so
-- "< 'Infinity'" refuses NaN as well as the infinities
ALTER TABLE runs ADD CONSTRAINT runs_figures_finite CHECK (
        (rms_before_um IS NULL OR (rms_before_um >= 0 AND rms_before_um < 'Infinity'))
    AND (rms_after_um  IS NULL OR (rms_after_um  >= 0 AND rms_after_um  < 'Infinity'))
    AND (gain          IS NULL OR (gain          >= 0 AND gain          < 'Infinity'))
    AND (ap_max_um     IS NULL OR (ap_max_um     >= 0 AND ap_max_um     < 'Infinity'))
    AND (rp_max_um     IS NULL OR (rp_max_um     >= 0 AND rp_max_um     < 'Infinity'))
    AND (drift_rms_um  IS NULL OR (drift_rms_um  >= 0 AND drift_rms_um  < 'Infinity'))
    AND (drift_max_um  IS NULL OR (drift_max_um  >= 0 AND drift_max_um  < 'Infinity'))
    AND (tolerance_um  IS NULL OR (tolerance_um  >= 0 AND tolerance_um  < 'Infinity'))) NOT VALID;
ALTER TABLE runs ADD CONSTRAINT runs_detail_object
    CHECK (jsonb_typeof(detail) = 'object' AND jsonb_typeof(fingerprint) = 'object') NOT VALID;

-- A robot's calibrations and rechecks that count (not rehearsals), newest first: the fleet page's
-- per-robot probes.
CREATE INDEX runs_robot_kind_real_time ON runs (robot_key, kind, finished_utc DESC) WHERE NOT simulated;

-- PostgreSQL 13 and 14 (which docs/fleet.md allows) still grant CREATE on schema public to every
-- role: a station's login could create tables there. 15 and later revoke it by default.
REVOKE CREATE ON SCHEMA public FROM PUBLIC;
