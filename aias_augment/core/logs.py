"""Logging flags shared by every command line: ``--log-level`` and ``--quiet``.

Levels apply to the project's own loggers (``aias_augment``, ``detection_eval``). Other libraries' loggers (PyOpenGL's
``OpenGL.acceleratesupport`` INFO line, trimesh, pyrender, PIL ...) stay at WARNING unless ``--log-level DEBUG``
asks for everything. ``--quiet`` keeps errors only: ERROR for every logger, Python warnings included (they are
routed through the ``py.warnings`` logger), and no progress bar (:func:`progress_disabled`).
"""

from __future__ import annotations

import argparse
import logging
from collections.abc import Iterable

LOG_LEVELS = ("DEBUG", "INFO", "WARNING", "ERROR")
#: Top-level loggers of this project: they take ``--log-level`` as given; every other logger is held at WARNING
#: (or ERROR with ``--quiet``) unless the level is DEBUG.
PROJECT_LOGGERS = ("aias_augment", "detection_eval")
DEFAULT_FORMAT = "%(levelname)s %(name)s: %(message)s"


def add_logging_args(
    parser: argparse.ArgumentParser, default: str = "WARNING", subcommands: Iterable[argparse.ArgumentParser] = ()
) -> None:
    """Add ``--log-level {DEBUG,INFO,WARNING,ERROR}`` (default ``default``) and ``--quiet`` to ``parser``, and to
    each parser in ``subcommands`` (so that ``prog sub --quiet`` works as well as ``prog --quiet sub``)."""
    if default not in LOG_LEVELS:
        raise ValueError(f"default log level {default!r} is not one of {LOG_LEVELS}")
    _add_flags(parser, default, default)
    for sub in {id(s): s for s in subcommands}.values():
        # SUPPRESS: a flag not given after the subcommand leaves the value parsed before it in place.
        _add_flags(sub, argparse.SUPPRESS, default)


def _add_flags(parser: argparse.ArgumentParser, default: str, default_name: str) -> None:
    g = parser.add_argument_group("logging")
    g.add_argument(
        "--log-level",
        choices=LOG_LEVELS,
        default=default,
        help=f"this project's messages at this level and above (default {default_name}); other libraries' messages "
        "show at WARNING and above, all of them with DEBUG",
    )
    g.add_argument(
        "--quiet",
        action="store_true",
        default=False if default != argparse.SUPPRESS else argparse.SUPPRESS,
        help="errors only: no progress bar, no warnings, no info (overrides --log-level)",
    )


def log_level(args: argparse.Namespace) -> int:
    """The ``logging`` level that ``args`` (parsed with :func:`add_logging_args`) asks for."""
    return logging.ERROR if args.quiet else getattr(logging, args.log_level)


def configure_logging(args: argparse.Namespace, fmt: str = DEFAULT_FORMAT) -> int:
    """Route every log record to stderr at the levels ``args`` asks for (see the module docstring); returns the
    project's level. Replaces handlers an earlier call or import installed on the root logger."""
    level = log_level(args)
    library_level = level if level == logging.DEBUG else max(level, logging.WARNING)
    logging.basicConfig(level=library_level, format=fmt, force=True)
    for name in PROJECT_LOGGERS:
        logging.getLogger(name).setLevel(level)
    # Off, then on: logging installs its hook only when it believes none is installed, and a caller that restored
    # warnings.showwarning since an earlier call (a test harness, a catch_warnings block) would leave it out.
    logging.captureWarnings(False)
    logging.captureWarnings(True)
    return level


def progress_disabled(logger: logging.Logger) -> bool:
    """True where progress bars are unwanted: ``logger`` drops WARNING (``--quiet``)."""
    return not logger.isEnabledFor(logging.WARNING)
