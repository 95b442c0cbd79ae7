-- Policy endpoints' bearer tokens are kept sealed at rest (issue 23): `submissions.body` holds
-- `token_sealed` (ChaCha20-Poly1305 under the server's secret key, `[secrets] key_file`) instead
-- of the plain `token`, and a job's `spec` holds `endpoint.bearer_token_sealed` with
-- `endpoint.bearer_token` left empty; workers get the token opened at lease time.
--
-- SQL cannot encrypt, so the rows written before this migration are sealed by the server at
-- start-up (server/src/store/secrets.rs), in batches, before it serves. This one-row table says
-- that step is still to do: the server deletes the row in the transaction of its last batch, so
-- later starts do not scan the jobs again, and a server stopped half-way resumes at its next
-- start. Nothing is lost: every token is kept, only sealed.
CREATE TABLE pending_token_sealing (
    id  INTEGER PRIMARY KEY CHECK (id = 1)
);
INSERT INTO pending_token_sealing (id) VALUES (1);
