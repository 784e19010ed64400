"""The package's error bases: ``AiasError`` is the base of every exception class that aias_augment and
detection_eval define, so ``except AiasError`` catches any project error; each class also keeps its builtin base
(``ValueError``, ``RuntimeError``, ...), so callers that catch those still do. Imports nothing from the package."""


class AiasError(Exception):
    """The base of every error the project raises by its own class."""


class InputError(AiasError, ValueError):
    """A problem with the whole input (or the arguments): nothing sensible can be produced."""
