"""What each stage did, for people and for code: a :class:`StageNote` reads as its text (what was used, with its
numbers, or ``"skipped: why"``) and carries its status as a field, so code decides on ``note.skipped`` and never on
the words. Records store the skipped stages' names beside the texts (:func:`skipped_stages`) and read them back
with :func:`notes_from_dict`."""

from __future__ import annotations

from collections.abc import Iterable, Mapping

__all__ = ["StageNote", "skipped", "skipped_stages", "notes_from_dict"]


class StageNote(str):
    """A stage's report: the string is the text for people, ``skipped`` the status for code."""

    skipped: bool

    def __new__(cls, text: str, *, skipped: bool = False) -> StageNote:
        note = super().__new__(cls, text)
        note.skipped = bool(skipped)
        return note

    def __reduce__(self):  # pickled (Ray, spawned workers) with its status
        return (_note, (str(self), self.skipped))


def _note(text: str, is_skipped: bool) -> StageNote:
    return StageNote(text, skipped=is_skipped)


def skipped(why: str) -> StageNote:
    """The note of a stage that did not run: ``"skipped: why"``, status skipped."""
    return StageNote(f"skipped: {why}", skipped=True)


def skipped_stages(notes: Mapping[str, str]) -> list[str]:
    """The names of the stages whose note says, by its status, that they were skipped (sorted)."""
    return sorted(k for k, v in notes.items() if getattr(v, "skipped", False))


def notes_from_dict(texts: Mapping[str, str], skipped_names: Iterable[str]) -> dict[str, StageNote]:
    """Notes read back from a record: the texts with the stored skipped stages' status."""
    names = set(skipped_names)
    unknown = names - set(texts)
    if unknown:
        raise ValueError(f"skipped stages {sorted(unknown)} have no note in the record")
    return {k: StageNote(v, skipped=k in names) for k, v in texts.items()}
