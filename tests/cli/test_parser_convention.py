"""The command-line convention, checked on every parser of ``scpformer``.

Every option is lowercase kebab-case (an old spelling survives only as a hidden alias that
warns and names the new flag), every flag with an enumerated set of values lists them as
``choices``, no help text points into the source, and ``--version`` says what is installed.
"""

from __future__ import annotations

import argparse
import re
import shutil
import subprocess
from collections.abc import Iterator
from pathlib import Path

import pytest

import scpformer
from scpformer.cli.main import build_parser, main

KEBAB = re.compile(r"^--[a-z0-9]+(?:-[a-z0-9]+)*$")
SOURCE_POINTER = re.compile(
    r"see the module|module docstring|scpformer\.[a-z_]+\.|\bsrc/|\w\.py\b", re.IGNORECASE
)
#: flags whose value is free text by nature (no set of values to list), and why
FREE_TEXT = {
    "--ray": "a Ray cluster address ('auto', 'local' or host:port)",
}


def walk(parser: argparse.ArgumentParser, path: tuple[str, ...] = ()) -> Iterator[
    tuple[tuple[str, ...], argparse.ArgumentParser]
]:  # fmt: skip
    """Every parser under ``parser`` (the lazy command parsers built), with its command."""
    yield path, parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name in list(action.choices):
                yield from walk(action.choices[name], (*path, name))


PARSERS = dict(walk(build_parser()))


def is_alias(action: argparse.Action) -> bool:
    """A hidden old spelling of a flag (``add_deprecated_alias`` of the flag builder)."""
    return hasattr(action, "new_flag")


def options(parser: argparse.ArgumentParser) -> Iterator[argparse.Action]:
    for action in parser._actions:
        if action.option_strings and not isinstance(action, argparse._HelpAction):
            yield action


def test_the_walk_reaches_every_command():
    commands = {" ".join(path) for path in PARSERS}
    assert {"solve pdg6dof", "solve rendezvous", "solve robust-rendezvous", "bench art",
            "generate rendezvous", "dataset split", "train tscvx", "train kdtree",
            "experiment", "export", "demo", "report"} <= commands  # fmt: skip
    assert len(PARSERS) >= 30


@pytest.mark.parametrize("command", [" ".join(p) or "scpformer" for p in PARSERS])
def test_every_option_is_lowercase_kebab_case(command):
    parser = PARSERS[tuple(command.split()) if command != "scpformer" else ()]
    wrong = [
        option
        for action in options(parser)
        if not is_alias(action)
        for option in action.option_strings
        if not KEBAB.match(option)
    ]
    assert not wrong, f"{command}: {wrong}"


@pytest.mark.parametrize("command", [" ".join(p) for p in PARSERS if p])
def test_every_alias_is_hidden_and_names_a_flag_of_its_command(command):
    parser = PARSERS[tuple(command.split())]
    by_option = {o: a for a in options(parser) if not is_alias(a) for o in a.option_strings}
    for action in options(parser):
        if is_alias(action):
            assert action.help == argparse.SUPPRESS, action.option_strings
            new = by_option.get(action.new_flag)
            assert new is not None, f"{action.option_strings} -> {action.new_flag}"
            assert new.dest == action.dest
            assert KEBAB.match(action.new_flag)


def test_an_old_spelling_warns_naming_the_new_one_and_works(capsys):
    assert main(["solve", "pdg6dof", "--const-T-max", "5", "--print-config"]) == 0
    out, err = capsys.readouterr()
    assert err == (
        "scpformer: warning: --const-T-max is deprecated and will be removed; use --const-t-max\n"
    )
    section = out.split("[const]\n", 1)[1]
    assert "t-max = 5.0" in section.splitlines()
    # the new spelling, the same value and no warning
    assert main(["solve", "pdg6dof", "--const-t-max", "5", "--print-config"]) == 0
    new_out, new_err = capsys.readouterr()
    assert new_out == out and new_err == ""


@pytest.mark.parametrize("command", [" ".join(p) or "scpformer" for p in PARSERS])
def test_every_flag_of_words_lists_its_choices(command):
    """A flag that takes words (no number, no path) names its values as ``choices``."""
    parser = PARSERS[tuple(command.split()) if command != "scpformer" else ()]
    missing = [
        action.option_strings[0]
        for action in options(parser)
        if action.nargs != 0
        and action.type in (None, str)
        and action.choices is None
        and not is_alias(action)
        and not isinstance(action, argparse._VersionAction)
        and action.option_strings[0] not in FREE_TEXT
    ]
    assert not missing, f"{command}: {missing} take words but list no choices"


@pytest.mark.parametrize("command", [" ".join(p) or "scpformer" for p in PARSERS])
def test_no_help_points_into_the_source(command):
    parser = PARSERS[tuple(command.split()) if command != "scpformer" else ()]
    texts = [parser.description or "", parser.epilog or ""]
    texts += [a.help for a in parser._actions if a.help and a.help != argparse.SUPPRESS]
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            texts += [choice.help or "" for choice in action._choices_actions]
    pointers = [text for text in texts if SOURCE_POINTER.search(text)]
    assert not pointers, f"{command}: {pointers}"


def test_the_source_pointer_pattern_finds_pointers():
    for text in ("see the module docstring", "(see scpformer.scp.conic.SOLVERS)",
                 "src/scpformer/cli/main.py", "defined in problem.py"):  # fmt: skip
        assert SOURCE_POINTER.search(text), text
    assert not SOURCE_POINTER.search("print the version (and git commit) and exit")


def _git_commit() -> str | None:
    folder = Path(scpformer.__file__).resolve().parent
    if shutil.which("git") is None or not (folder.parent.parent / ".git").exists():
        return None
    done = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=folder,
                          capture_output=True, text=True, check=False)  # fmt: skip
    return done.stdout.strip() if done.returncode == 0 else None


def test_version_prints_the_version_and_the_commit_of_a_checkout(capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # the package's checkout, not the working folder's
    assert main(["--version"]) == 0
    out = capsys.readouterr().out
    expected = f"scpformer {scpformer.__version__}"
    commit = _git_commit()
    if commit is not None:
        expected += f" (commit {commit})"
    assert out == expected + "\n"
    assert re.match(r"^scpformer \d+\.\d+", out)
