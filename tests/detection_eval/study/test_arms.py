from __future__ import annotations

from detection_eval.study.arms import ARM_FLAGS


def test_closeup_arm_is_a_study_flag_not_an_insertion_override():
    from detection_eval.study.arms import STUDY_FLAGS

    assert ARM_FLAGS["inserted_closeup"] == {"closeup_crop": True} and "closeup_crop" in STUDY_FLAGS
