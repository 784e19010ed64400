"""The step packages offer their entry points lazily: the names are the modules' own objects, and importing one
module of a step does not import the others."""

import subprocess
import sys

import pytest


@pytest.mark.parametrize(
    "package, name, module",
    [
        ("aias_augment.analyse", "analyse_scene", "aias_augment.analyse.analysis"),
        ("aias_augment.analyse", "SceneCache", "aias_augment.analyse.cache"),
        ("aias_augment.plan", "plan_insertion", "aias_augment.plan.insertion"),
        ("aias_augment.apply", "apply_plan", "aias_augment.apply.stages"),
        ("aias_augment.pipeline", "insert_into_image", "aias_augment.pipeline.image"),
        ("aias_augment.pipeline", "load_preset", "aias_augment.pipeline.config"),
    ],
)
def test_a_step_package_serves_its_modules_objects(package, name, module):
    import importlib

    assert getattr(importlib.import_module(package), name) is getattr(importlib.import_module(module), name)


def test_an_unknown_name_is_an_attribute_error():
    import aias_augment.plan

    with pytest.raises(AttributeError, match="no attribute 'plan_everything'"):
        aias_augment.plan.plan_everything


def test_importing_one_module_of_a_step_does_not_import_the_step():
    code = (
        "import sys, aias_augment.plan.collision; "
        "print(sorted(m for m in sys.modules if m.startswith('aias_augment.plan.')))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "['aias_augment.plan.collision']"
