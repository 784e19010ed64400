"""The package's error for a bad input as a whole: nothing sensible can be produced from it."""


class InputError(ValueError):
    """A problem with the whole input (or the arguments): nothing sensible can be produced."""
