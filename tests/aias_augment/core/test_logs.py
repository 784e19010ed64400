"""``--log-level`` / ``--quiet``: which records reach stderr, from this project's loggers and from other libraries'."""

from __future__ import annotations

import argparse
import logging
import warnings

import pytest

from aias_augment.core.logs import PROJECT_LOGGERS, add_logging_args, configure_logging, progress_disabled

LIBRARY = "OpenGL.acceleratesupport"  # a third-party logger that speaks at INFO on every import of PyOpenGL


@pytest.fixture(autouse=True)
def restore_logging():
    root = logging.getLogger()
    saved = (list(root.handlers), root.level, {n: logging.getLogger(n).level for n in (*PROJECT_LOGGERS, LIBRARY)})
    yield
    root.handlers[:] = saved[0]
    root.setLevel(saved[1])
    for name, level in saved[2].items():
        logging.getLogger(name).setLevel(level)
    logging.captureWarnings(False)


def _parser(default="WARNING"):
    p = argparse.ArgumentParser(prog="x")
    sub = p.add_subparsers(dest="cmd", required=True)
    sub.add_parser("run")
    add_logging_args(p, default=default, subcommands=sub.choices.values())
    return p


def _emit():
    for name in ("aias_augment.cli.offline", "detection_eval.train", LIBRARY):
        lg = logging.getLogger(name)
        for level in (logging.DEBUG, logging.INFO, logging.WARNING, logging.ERROR):
            lg.log(level, "m")
    with warnings.catch_warnings():
        warnings.simplefilter("always")
        warnings.warn("w", UserWarning)


def _lines(argv, capsys, default="WARNING"):
    configure_logging(_parser(default).parse_args(argv))
    _emit()
    err = capsys.readouterr().err
    lines = [ln.split() for ln in err.splitlines()]
    # A warning's record carries the source line on a second, indented line.
    return {(w[0], w[1].rstrip(":")) for w in lines if w and w[0] in ("DEBUG", "INFO", "WARNING", "ERROR")}


def _expected(project_levels, library_levels, warning):
    out = {(lvl, n) for n in ("aias_augment.cli.offline", "detection_eval.train") for lvl in project_levels}
    out |= {(lvl, LIBRARY) for lvl in library_levels}
    return out | ({("WARNING", "py.warnings")} if warning else set())


@pytest.mark.parametrize(
    "argv, project, library, warning",
    [
        (["run"], ("WARNING", "ERROR"), ("WARNING", "ERROR"), True),
        (["--log-level", "INFO", "run"], ("INFO", "WARNING", "ERROR"), ("WARNING", "ERROR"), True),
        (["run", "--log-level", "INFO"], ("INFO", "WARNING", "ERROR"), ("WARNING", "ERROR"), True),
        (
            ["run", "--log-level", "DEBUG"],
            ("DEBUG", "INFO", "WARNING", "ERROR"),
            ("DEBUG", "INFO", "WARNING", "ERROR"),
            True,
        ),
        (["run", "--log-level", "ERROR"], ("ERROR",), ("ERROR",), False),
        (["--quiet", "run"], ("ERROR",), ("ERROR",), False),
        (["run", "--quiet", "--log-level", "DEBUG"], ("ERROR",), ("ERROR",), False),
    ],
)
def test_levels_reach_stderr(argv, project, library, warning, capsys):
    assert _lines(argv, capsys) == _expected(project, library, warning)


def test_a_cli_default_of_info_keeps_libraries_at_warning(capsys):
    assert _lines(["run"], capsys, default="INFO") == _expected(
        ("INFO", "WARNING", "ERROR"), ("WARNING", "ERROR"), True
    )


def test_flag_before_the_subcommand_is_kept_when_not_repeated_after_it():
    a = _parser().parse_args(["--quiet", "--log-level", "DEBUG", "run"])
    assert (a.quiet, a.log_level) == (True, "DEBUG")
    a = _parser().parse_args(["run"])
    assert (a.quiet, a.log_level) == (False, "WARNING")


def test_progress_bars_only_off_when_quiet():
    log = logging.getLogger("aias_augment.cli.offline")
    configure_logging(_parser().parse_args(["run"]))
    assert not progress_disabled(log)
    configure_logging(_parser().parse_args(["run", "--quiet"]))
    assert progress_disabled(log)


def test_unknown_default_is_refused():
    with pytest.raises(ValueError, match="VERBOSE"):
        add_logging_args(argparse.ArgumentParser(), default="VERBOSE")


def test_warnings_reach_the_log_after_a_hook_left_on_and_showwarning_restored(capsys):
    """An earlier in-process CLI call leaves logging's warnings hook on; a harness then restores
    ``warnings.showwarning``. The next ``configure_logging`` must still route warnings to the log."""
    logging.captureWarnings(True)
    warnings.showwarning = warnings._showwarning_orig  # what catch_warnings / pytest restore between calls
    configure_logging(_parser().parse_args(["run"]))
    with warnings.catch_warnings():
        warnings.simplefilter("always")
        warnings.warn("w", UserWarning)
    assert "py.warnings" in capsys.readouterr().err
