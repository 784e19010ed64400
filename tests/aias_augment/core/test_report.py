"""core.report: a stage's status travels as a field (pickle, records), never read from its text."""

import pickle

import pytest

from aias_augment.adapters.boundary import nothing_inserted_reason
from aias_augment.core.report import StageNote, notes_from_dict, skipped, skipped_stages


def test_status_is_a_field_that_survives_pickling_and_records():
    notes = {"shadow": skipped("disabled"), "lighting": StageNote("sun from the sky"), "ground": "prior"}
    assert notes["shadow"] == "skipped: disabled" and notes["shadow"].skipped and not notes["lighting"].skipped
    back = pickle.loads(pickle.dumps(notes))
    assert back == notes and back["shadow"].skipped and not back["lighting"].skipped
    assert skipped_stages(notes) == ["shadow"]
    read = notes_from_dict({k: str(v) for k, v in notes.items()}, ["shadow"])
    assert read == notes and [k for k, v in read.items() if v.skipped] == ["shadow"]
    with pytest.raises(ValueError, match="no note"):
        notes_from_dict({"shadow": "x"}, ["harmonize"])


def test_the_reason_for_nothing_inserted_follows_the_status_not_the_words():
    record = {
        "modules": {"shadow": "skipped: disabled", "lighting": "skipped frames fused into one sun"},
        "skipped_stages": ["shadow"],
        "placement_reports": [{"rejected": {"outside the image": 3, "too small in the image": 1}}],
    }
    reason = nothing_inserted_reason(record)
    assert reason == "shadow skipped: disabled; placements rejected, most often: outside the image"
