-- Rescoring covers every track. A policy run's scores come from simulated episodes; a rescore
-- recomputes them (SR, MSE, and M and P against the linked plans) from the episodes already
-- recorded, as a new scoring run that points at the run whose episodes it read. Episodes stay
-- keyed by the run that simulated them.
ALTER TABLE scoring_runs ADD COLUMN source_run_id INTEGER REFERENCES scoring_runs(id);
-- Set on a policy run whose episodes no longer match the ground truth (an instruction's plan or
-- place targets changed): its scores cannot be recomputed without simulating again, which needs
-- the participant's endpoint, so it is re-run only on an organiser's request.
ALTER TABLE scoring_runs ADD COLUMN needs_resimulation INTEGER NOT NULL DEFAULT 0;
