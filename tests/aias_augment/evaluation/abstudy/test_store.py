import sqlite3
import threading

import pytest

from aias_augment.evaluation.abstudy.store import DuplicateVote, VoteStore


def test_vote_roundtrip_wal_and_duplicate(tmp_path):
    db = tmp_path / "votes.sqlite"
    s = VoteStore(db)
    assert sqlite3.connect(db).execute("PRAGMA journal_mode").fetchone()[0] == "wal"
    s.add_vote("ann", "aaaaaaaaaaaa", "left", "full", "naive", ms=1200)
    s.add_vote("ann", "bbbbbbbbbbbb", "tie", "naive", "full")
    s.add_vote("bob", "aaaaaaaaaaaa", "right", "full", "naive")
    with pytest.raises(DuplicateVote) as e:
        s.add_vote("ann", "aaaaaaaaaaaa", "right", "full", "naive")
    assert e.value.stored_choice == "left"
    assert s.voted_pairs("ann") == {"aaaaaaaaaaaa", "bbbbbbbbbbbb"} and s.count() == 3
    v = {(r["rater"], r["pair_id"]): r for r in s.votes()}
    assert v[("ann", "aaaaaaaaaaaa")]["choice"] == "left" and v[("ann", "aaaaaaaaaaaa")]["ms"] == 1200
    assert v[("ann", "bbbbbbbbbbbb")]["ms"] is None
    with pytest.raises(ValueError):
        s.add_vote("ann", "cccccccccccc", "up", "full", "naive")
    # a new store on the same file (a restarted server) sees every vote
    assert VoteStore(db).count() == 3


def test_concurrent_writers_lose_nothing(tmp_path):
    s = VoteStore(tmp_path / "votes.sqlite")
    errors, dups = [], []

    def rater(r):
        try:
            for p in range(40):
                s.add_vote(f"r{r}", f"{p:012x}", ("left", "right", "tie")[p % 3], "a", "b")
                if p % 10 == 0:
                    try:
                        s.add_vote(f"r{r}", f"{p:012x}", "left", "a", "b")
                    except DuplicateVote:
                        dups.append(1)
        except Exception as e:  # pragma: no cover - reported below
            errors.append(e)

    threads = [threading.Thread(target=rater, args=(r,)) for r in range(8)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not errors
    assert s.count() == 8 * 40 and len(dups) == 8 * 4
