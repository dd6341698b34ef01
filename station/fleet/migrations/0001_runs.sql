-- The fleet store: every station's published runs. One row per run, keyed by the run's UUID
-- (publishing is idempotent: a second insert of the same UUID does nothing).
CREATE TABLE robots (
    robot_key   TEXT PRIMARY KEY,                -- the robot's serial, or station/cell where none is given
    serial      TEXT,
    first_seen  TIMESTAMPTZ NOT NULL DEFAULT now()
);

CREATE TABLE runs (
    id                     BIGSERIAL PRIMARY KEY,
    run_uuid               UUID NOT NULL UNIQUE,
    robot_key              TEXT NOT NULL REFERENCES robots (robot_key),
    robot_serial           TEXT,
    robot_model            TEXT NOT NULL,
    cell                   TEXT NOT NULL,
    station                TEXT NOT NULL,
    station_version        TEXT NOT NULL,
    local_run_id           BIGINT NOT NULL,
    kind                   TEXT NOT NULL CHECK (kind IN ('calibration', 'recheck')),
    outcome                TEXT NOT NULL,
    started_utc            TIMESTAMPTZ NOT NULL,
    finished_utc           TIMESTAMPTZ NOT NULL,
    rms_before_um          DOUBLE PRECISION,
    rms_after_um           DOUBLE PRECISION,
    gain                   DOUBLE PRECISION,
    ap_max_um              DOUBLE PRECISION,
    rp_max_um              DOUBLE PRECISION,
    drift_rms_um           DOUBLE PRECISION,
    drift_max_um           DOUBLE PRECISION,
    tolerance_um           DOUBLE PRECISION,
    recheck_interval_days  INTEGER,
    fingerprint            JSONB NOT NULL DEFAULT '{}'::jsonb,
    detail                 JSONB NOT NULL DEFAULT '{}'::jsonb,   -- summary, parameters with covariance, certificates
    received_utc           TIMESTAMPTZ NOT NULL DEFAULT now()
);

CREATE TABLE reports (
    run_uuid      UUID PRIMARY KEY REFERENCES runs (run_uuid),
    path          TEXT NOT NULL,                 -- where the station wrote it
    html          TEXT NOT NULL,                 -- the self-contained report.html as written
    received_utc  TIMESTAMPTZ NOT NULL DEFAULT now()
);
