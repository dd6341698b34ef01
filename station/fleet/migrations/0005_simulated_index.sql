-- Issue 39: a robot's latest rehearsal (the fleet page's 'last_simulated' probe) without reading
-- its whole history. Schema 4's only index on 'simulated' is partial on NOT simulated, so the probe
-- for a robot with no rehearsal walked all its runs: 377 200 rows for 200 robots × 5 years, the
-- fleet page 548 ms (benchmarks/bench_fleet.py; 48 ms before schema 4). This partial index holds
-- the rehearsals only: near-empty in a plant, one probe per robot.
CREATE INDEX runs_robot_simulated_time ON runs (robot_key, finished_utc DESC) WHERE simulated;
