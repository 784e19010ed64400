"""Votes in SQLite: one row per (rater, pair), written in WAL mode with a full sync, so concurrent raters lose no
vote and a vote that was answered with 201 survives a killed server.

Each call opens its own connection (cheap for SQLite; no connection is shared between threads). A second vote of
the same rater on the same pair violates the primary key and raises ``DuplicateVote`` with the stored choice.
"""

from __future__ import annotations

import sqlite3
import time
from contextlib import closing
from pathlib import Path

from aias_augment.core.errors import AiasError

CHOICES = ("left", "right", "tie")

SCHEMA = """
CREATE TABLE IF NOT EXISTS votes (
    rater      TEXT NOT NULL,
    pair_id    TEXT NOT NULL,
    choice     TEXT NOT NULL CHECK (choice IN ('left', 'right', 'tie')),
    left_arm   TEXT NOT NULL,
    right_arm  TEXT NOT NULL,
    ms         INTEGER,                 -- time from showing the pair to the vote, as the page measured it
    created    REAL NOT NULL,           -- unix time at the server
    PRIMARY KEY (rater, pair_id)
);
CREATE TABLE IF NOT EXISTS raters (
    rater      TEXT PRIMARY KEY,
    created    REAL NOT NULL
);
"""


class DuplicateVote(AiasError):
    def __init__(self, stored_choice: str):
        super().__init__(f"already voted: {stored_choice}")
        self.stored_choice = stored_choice


class VoteStore:
    def __init__(self, path: str | Path, timeout_s: float = 30.0):
        self.path = Path(path)
        self.timeout_s = timeout_s
        with closing(self._connect()) as con:
            mode = con.execute("PRAGMA journal_mode=WAL").fetchone()[0]
            if mode.lower() != "wal":
                raise RuntimeError(f"{self.path}: SQLite refused WAL mode (got {mode})")
            con.executescript(SCHEMA)
            con.commit()

    def _connect(self) -> sqlite3.Connection:
        con = sqlite3.connect(self.path, timeout=self.timeout_s, isolation_level=None)
        con.execute(f"PRAGMA busy_timeout={int(self.timeout_s * 1000)}")
        con.execute("PRAGMA synchronous=FULL")
        return con

    def add_rater(self, rater: str) -> None:
        with closing(self._connect()) as con:
            con.execute("INSERT OR IGNORE INTO raters (rater, created) VALUES (?, ?)", (rater, time.time()))

    def add_vote(
        self, rater: str, pair_id: str, choice: str, left_arm: str, right_arm: str, ms: int | None = None
    ) -> None:
        if choice not in CHOICES:
            raise ValueError(f"choice must be one of {CHOICES}, got {choice!r}")
        with closing(self._connect()) as con:
            try:
                con.execute("BEGIN IMMEDIATE")
                con.execute("INSERT OR IGNORE INTO raters (rater, created) VALUES (?, ?)", (rater, time.time()))
                con.execute(
                    "INSERT INTO votes (rater, pair_id, choice, left_arm, right_arm, ms, created) "
                    "VALUES (?, ?, ?, ?, ?, ?, ?)",
                    (rater, pair_id, choice, left_arm, right_arm, ms, time.time()),
                )
                con.execute("COMMIT")
            except sqlite3.IntegrityError:
                con.execute("ROLLBACK")
                row = con.execute(
                    "SELECT choice FROM votes WHERE rater = ? AND pair_id = ?", (rater, pair_id)
                ).fetchone()
                if row is None:  # not the primary key: a CHECK failed
                    raise
                raise DuplicateVote(row[0]) from None

    def voted_pairs(self, rater: str) -> set[str]:
        with closing(self._connect()) as con:
            return {r[0] for r in con.execute("SELECT pair_id FROM votes WHERE rater = ?", (rater,))}

    def votes(self) -> list[dict]:
        with closing(self._connect()) as con:
            con.row_factory = sqlite3.Row
            rows = con.execute(
                "SELECT rater, pair_id, choice, left_arm, right_arm, ms, created FROM votes "
                "ORDER BY created, rater, pair_id"
            ).fetchall()
            return [dict(r) for r in rows]

    def count(self) -> int:
        with closing(self._connect()) as con:
            return int(con.execute("SELECT COUNT(*) FROM votes").fetchone()[0])
