-- Teams and their API tokens. Only the SHA-256 of a token is stored: a leaked database does not
-- let anyone submit as a team.
CREATE TABLE teams (
    id          INTEGER PRIMARY KEY AUTOINCREMENT,
    name        TEXT    NOT NULL UNIQUE,
    token_hash  TEXT    NOT NULL UNIQUE,   -- hex sha256 of the bearer token
    created_at  INTEGER NOT NULL           -- Unix milliseconds, UTC
);
