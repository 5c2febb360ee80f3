"""The ``scpformer`` command: ``solve`` and ``bench`` per family, ``generate``, ``dataset``,
``train``, ``experiment``, ``report``, ``demo``, ``export``.

Only this module, :mod:`scpformer.cli.commands` and a command's parser module
(:mod:`scpformer.cli.parsers`) are imported to build the parser; a command's handler (and
cvxpy, torch, ...) is imported when the command runs.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from scpformer.cli.commands import LazySubParsersAction, add_lazy_commands
from scpformer.cli.config_file import ConfigParser
from scpformer.cli.errors import run_command


def git_commit(folder: Path) -> str | None:
    """The short commit of the git checkout holding the package ``folder``, or None (not a
    checkout, or no git)."""
    import subprocess  # only --version needs it

    try:
        done = subprocess.run(
            ["git", "rev-parse", "--short", "HEAD", "--show-toplevel"],
            cwd=folder,
            capture_output=True,
            text=True,
            timeout=5,
            check=False,
        )
    except (OSError, subprocess.SubprocessError):
        return None
    lines = done.stdout.splitlines()
    if done.returncode != 0 or len(lines) != 2:
        return None
    # git prints the two answers in an order of its own (the top level first, in git 2.39)
    tops = [line for line in lines if Path(line).is_absolute()]
    if len(tops) != 1:
        return None
    top = tops[0]
    commit = lines[1 - lines.index(top)]
    # only the checkout of this package's source (src/scpformer), not a repository that
    # happens to hold an installed copy
    if (Path(top) / "src" / "scpformer").resolve() != folder.resolve():
        return None
    return commit


def version_text() -> str:
    """``scpformer X.Y.Z`` and, in a git checkout, ``(commit abc1234)``."""
    import scpformer

    text = f"scpformer {scpformer.__version__}"
    commit = git_commit(Path(scpformer.__file__).resolve().parent)
    return f"{text} (commit {commit})" if commit else text


class _VersionAction(argparse._VersionAction):
    """``--version``: reads the package metadata (and the git commit) only when asked."""

    def __call__(self, parser, namespace, values, option_string=None) -> None:
        self.version = version_text()
        super().__call__(parser, namespace, values, option_string)


def build_parser() -> argparse.ArgumentParser:
    parser = ConfigParser(
        prog="scpformer",
        description="Sequential convex programming for spacecraft trajectories.",
    )
    parser.add_argument(
        "--version", action=_VersionAction, help="print the version (and git commit) and exit"
    )
    commands = parser.add_subparsers(
        dest="command", required=True, metavar="COMMAND", action=LazySubParsersAction
    )
    solve = commands.add_parser("solve", help="solve one instance of a problem family")
    bench = commands.add_parser("bench", help="benchmark a solver on a seeded instance set")
    for command, sub in (("solve", solve), ("bench", bench)):
        families = sub.add_subparsers(
            dest="family", required=True, metavar="FAMILY", action=LazySubParsersAction
        )
        add_lazy_commands(families, command)
    add_lazy_commands(commands, "")
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point; every failure ends with one ``scpformer: error:`` line (see cli.errors)."""
    return run_command(build_parser(), argv)


if __name__ == "__main__":
    sys.exit(main())
