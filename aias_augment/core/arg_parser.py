"""The argument parser of every command line: a usage error is one stderr line and exit 2.

argparse prints its usage block (several lines, the whole option list for a large command) before the error; a
user then scrolls past it to find what was wrong. Here the error line alone is printed, naming the command and
pointing to ``--help``. Subcommand parsers inherit the class (``add_subparsers`` makes parsers of the parent's type).
"""

from __future__ import annotations

import argparse


class OneLineArgumentParser(argparse.ArgumentParser):
    """``argparse.ArgumentParser`` whose usage errors are one line: ``<prog>: error: <message> (see <prog> --help)``,
    exit 2."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {' '.join(message.split())} (see {self.prog} --help)\n")
