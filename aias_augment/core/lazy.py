"""Names a package offers without importing them until first use (PEP 562): ``from aias_augment.plan import
plan_insertion`` reads well, while importing one module of the package (``aias_augment.plan.placement``) does not
pay for, or loop through, every other."""

import importlib


def lazy_exports(package: str, table: dict[str, str]):
    """A module ``__getattr__`` for ``package`` serving each name of ``table`` ({name: module}) from its module."""

    def __getattr__(name: str):
        if name in table:
            return getattr(importlib.import_module(table[name]), name)
        raise AttributeError(f"module {package!r} has no attribute {name!r}")

    return __getattr__
