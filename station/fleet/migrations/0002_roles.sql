-- Two group roles (NOLOGIN): a station may only insert runs; the dashboard may only read.
-- A plant gives each station and the dashboard its own login role in one of them, e.g.
--   CREATE ROLE cart1 LOGIN IN ROLE fleet_station;  CREATE ROLE qa LOGIN IN ROLE fleet_dashboard;
DO $$
BEGIN
    IF NOT EXISTS (SELECT 1 FROM pg_roles WHERE rolname = 'fleet_station') THEN
        CREATE ROLE fleet_station NOLOGIN;
    END IF;
    IF NOT EXISTS (SELECT 1 FROM pg_roles WHERE rolname = 'fleet_dashboard') THEN
        CREATE ROLE fleet_dashboard NOLOGIN;
    END IF;
END
$$;

REVOKE ALL ON robots, runs, reports FROM PUBLIC;
GRANT USAGE ON SCHEMA public TO fleet_station, fleet_dashboard;
GRANT INSERT ON robots, runs, reports TO fleet_station;
GRANT USAGE ON SEQUENCE runs_id_seq TO fleet_station;
GRANT SELECT ON fleet_schema_version TO fleet_station;
GRANT SELECT ON robots, runs, reports, fleet_schema_version TO fleet_dashboard;
