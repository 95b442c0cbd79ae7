-- Browser sessions of the HTML pages (issue #23). A login makes a random session id; the cookie
-- carries that id, never a credential, and only its SHA-256 is stored here, so a leaked
-- database does not open anyone's session. A session is bound to the credential it was opened
-- with (`credential_hash`, the hash of the token presented at login): rotating a team's token
-- or changing the organiser token ends every session opened with the old one. Logout deletes
-- the row; expired rows are deleted at the next login.
--
-- Cookies set before this migration held the hex of the token itself: they match no row here,
-- so their holders simply log in again.
CREATE TABLE sessions (
    id_hash         TEXT    PRIMARY KEY,             -- hex sha256 of the cookie's random id
    team_id         INTEGER REFERENCES teams(id),    -- NULL: an organiser session
    credential_hash TEXT    NOT NULL,                -- hex sha256 of the token the login presented
    created_at      INTEGER NOT NULL,                -- Unix milliseconds, UTC
    expires_at      INTEGER NOT NULL                 -- Unix milliseconds, UTC
);
CREATE INDEX sessions_team_id ON sessions (team_id);
CREATE INDEX sessions_expires_at ON sessions (expires_at);
