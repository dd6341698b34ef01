-- Issue 41: a run's Digital Calibration Certificate as the station wrote it ('station export-dcc'),
-- so that the dashboard serves the same bytes as the file. The store cannot rebuild one: a
-- certificate is made from the run's whole record (configuration, plan, every measurement), of
-- which the store keeps the summary and parameters, and from the issuer file (laboratory,
-- customer, approver), which no cell file holds.
--
-- A station's role only inserts: a certificate exported again (another approver, say) is a new
-- row, keyed by its digest; readers take the latest received. The digest is checked here, so a
-- row never holds other bytes than it names.
CREATE TABLE certificates (
    run_uuid        UUID NOT NULL REFERENCES runs (run_uuid),
    sha256          TEXT NOT NULL CHECK (sha256 = encode(sha256(xml), 'hex')),
    schema_version  TEXT NOT NULL,                 -- the DCC schema it was validated against
    xml             BYTEA NOT NULL,                -- the certificate, byte for byte
    received_utc    TIMESTAMPTZ NOT NULL DEFAULT now(),
    PRIMARY KEY (run_uuid, sha256)
);
CREATE INDEX certificates_run_time ON certificates (run_uuid, received_utc DESC);

REVOKE ALL ON certificates FROM PUBLIC;
GRANT INSERT ON certificates TO fleet_station;
GRANT SELECT ON certificates TO fleet_dashboard;
