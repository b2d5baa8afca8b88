"""The ``acps`` command of the Python package: the same command line as the Rust binary."""

from __future__ import annotations

import sys

from acps import _native


def main() -> None:
    """Run ``acps`` with this process's arguments and exit with its status."""
    # Workers and relays the command starts are this package's command too.
    sys.exit(_native.cli(["acps", *sys.argv[1:]], [sys.executable, "-m", "acps"]))
