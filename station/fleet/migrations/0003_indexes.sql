-- The fleet page (each robot's latest calibration and recheck) and a robot's history read
-- one robot's runs of one kind, newest first.
CREATE INDEX runs_robot_kind_time ON runs (robot_key, kind, finished_utc DESC);
CREATE INDEX runs_finished ON runs (finished_utc DESC);
