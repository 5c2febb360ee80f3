"""The command table and its lazily built parsers (``scpformer.cli.commands``)."""

from __future__ import annotations

import argparse
import json
import subprocess
import sys

import pytest

from scpformer.cli.commands import COMMANDS, LazySubParsersAction, add_lazy_commands
from scpformer.cli.main import build_parser, main

HEAVY = ("torch", "cvxpy", "scipy", "matplotlib", "ray", "h5py", "numpy", "clarabel")


def _imported_after(code: str) -> list[str]:
    """Heavy modules imported by a fresh interpreter running ``code``."""
    script = f"import sys\n{code}\nprint(__import__('json').dumps(sorted(sys.modules)))"
    done = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, check=True
    )
    loaded = set(json.loads(done.stdout.strip().splitlines()[-1]))
    return [name for name in HEAVY if name in loaded]


def _subparsers(parser: argparse.ArgumentParser) -> LazySubParsersAction:
    (action,) = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    return action


def test_help_imports_none_of_the_heavy_libraries():
    code = "from scpformer.cli.main import main\ntry: main(['--help'])\nexcept SystemExit: pass"
    assert _imported_after(code) == []


def test_solve_help_lists_the_families_without_importing_them():
    code = (
        "from scpformer.cli.main import main\n"
        "try: main(['solve', '--help'])\nexcept SystemExit: pass"
    )
    assert _imported_after(code) == []


def test_a_rendezvous_solve_imports_neither_torch_nor_plotting_nor_storage():
    code = (
        "from scpformer.cli.main import main\nmain(['solve', 'rendezvous', '--problem', 'tpbvp'])"
    )
    assert not {"torch", "matplotlib", "ray", "h5py"} & set(_imported_after(code))


def test_every_registered_command_builds_with_the_help_it_is_listed_with():
    parser = build_parser()
    top = _subparsers(parser)
    for (parent, name), (help_text, _) in COMMANDS.items():
        action = _subparsers(top.choices[parent]) if parent else top
        listed = {a.dest: a.help for a in action._choices_actions}
        assert listed[name] == help_text
        built = action.choices[name]  # imports the module and builds the parser
        assert isinstance(built, argparse.ArgumentParser)
        assert built.prog.endswith(f" {name}")


def test_commands_are_listed_in_their_registration_order(capsys):
    assert main(["no-such-command"]) == 2
    err = capsys.readouterr().err
    expected = (
        "'solve', 'bench', 'generate', 'dataset', 'train', 'experiment', 'report', 'demo', "
        "'export', 'simulate'"
    )
    assert f"invalid choice: 'no-such-command' (choose from {expected})" in err


def test_an_unknown_family_is_a_one_line_usage_error(capsys):
    assert main(["solve", "nope"]) == 2
    err = capsys.readouterr().err
    assert "choose from 'pdg6dof', 'rendezvous', 'robust-rendezvous'" in err
    assert err.count("\n") == 1


def _toy_parser(target: str, help_text: str = "a toy") -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="toy")
    sub = parser.add_subparsers(dest="command", action=LazySubParsersAction)
    sub.add_lazy_parser("toy", help=help_text, target=target)
    return parser


def add_toy_parser(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser("toy", help="a toy")
    parser.add_argument("--n", type=int, default=3)


def add_nothing(sub: argparse._SubParsersAction) -> None:
    """A builder that forgets its parser."""


def test_a_lazy_command_is_built_on_use_and_parses_its_flags():
    parser = _toy_parser(f"{__name__}:add_toy_parser")
    assert "toy" in parser.format_help() and "a toy" in parser.format_help()
    assert parser.parse_args(["toy", "--n", "5"]).n == 5


def test_a_builder_whose_help_differs_from_the_table_is_refused():
    parser = _toy_parser(f"{__name__}:add_toy_parser", help_text="another text")
    with pytest.raises(ValueError, match="help 'a toy' differs from 'another text'"):
        parser.parse_args(["toy"])


def test_a_builder_that_adds_no_parser_is_refused():
    parser = _toy_parser(f"{__name__}:add_nothing")
    with pytest.raises(ValueError, match="did not add the parser of 'toy'"):
        parser.parse_args(["toy"])


def test_lazy_commands_of_a_parent_are_all_registered():
    parser = argparse.ArgumentParser(prog="scpformer")
    families = parser.add_subparsers(dest="family", action=LazySubParsersAction)
    add_lazy_commands(families, "bench")
    assert list(families.choices) == ["pdg6dof", "rendezvous", "robust-rendezvous", "art", "tscvx"]
