from __future__ import annotations

from pathlib import Path

import pytest

from detection_eval.study.arms import ARM_FLAGS
from detection_eval.study.config import InsertionStudyConfig, StudyConfig, load_study_config

STUDIES = Path(__file__).resolve().parents[3] / "studies" / "detection"


def test_amounts_must_fit_the_pool():
    with pytest.raises(ValueError):
        StudyConfig(amounts=(700,), insertion=InsertionStudyConfig(pool_size=600))
    StudyConfig(amounts=(60, 600), insertion=InsertionStudyConfig(pool_size=600))


def test_study_configs_load_and_name_known_arms():
    core = load_study_config(STUDIES / "lite0_320" / "config.yaml")
    abl = load_study_config(STUDIES / "lite0_320" / "ablations.yaml")
    assert {"original", "inserted", "naive_paste"} <= set(core.arms) and len(core.seeds) >= 3
    assert set(abl.arms) == {"no_placement", "no_shadow", "no_lighting", "no_harmonize"}
    amounts = load_study_config(STUDIES / "lite0_320" / "amounts.yaml")
    for other in (abl, amounts):  # one pool per arm and the same runs: the tables can be read together
        assert (core.max_iters, core.insertion, core.detector, core.seeds) == (
            other.max_iters,
            other.insertion,
            other.detector,
            other.seeds,
        )
    assert len(core.seeds) >= 5 and set(amounts.amounts) | set(core.amounts) == {20, 60, 200}
    with pytest.raises(ValueError):
        StudyConfig(arms=("original", "bogus"))
    assert set(ARM_FLAGS) >= set(core.arms) | set(abl.arms)
