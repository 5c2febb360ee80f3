"""MkDocs hook: the command-line reference, rendered from the ``scpformer`` parser at build time.

A page holding the marker line ``<!-- scpformer-cli-reference -->`` gets, in its place, one
section per command and subcommand with the ``--help`` text that
:func:`scpformer.cli.main.build_parser` produces, so that the page can never disagree with the
command. Every lazily registered command is built (its module imported) here.
"""

from __future__ import annotations

import argparse
import os
from collections.abc import Iterator

MARKER = "<!-- scpformer-cli-reference -->"
WIDTH = "100"  # argparse wraps the help at $COLUMNS; a fixed width makes the page reproducible


def _subcommands(parser: argparse.ArgumentParser) -> Iterator[tuple[str, argparse.ArgumentParser]]:
    """``(name, parser)`` of every subcommand of ``parser``, in the order they are listed."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name in list(action.choices):
                yield name, action.choices[name]  # a lazy action builds the parser on lookup


def _walk(
    parser: argparse.ArgumentParser, path: tuple[str, ...]
) -> Iterator[tuple[tuple[str, ...], argparse.ArgumentParser]]:
    yield path, parser
    for name, child in _subcommands(parser):
        yield from _walk(child, (*path, name))


def render_reference() -> str:
    """Markdown: a section with the help text of every ``scpformer`` command."""
    from scpformer.cli.main import build_parser

    previous = os.environ.get("COLUMNS")
    os.environ["COLUMNS"] = WIDTH
    try:
        sections = []
        for path, parser in _walk(build_parser(), ("scpformer",)):
            level = "#" * min(len(path) + 1, 4)
            text = parser.format_help().rstrip()
            sections.append(f"{level} `{' '.join(path)}`\n\n```text\n{text}\n```\n")
    finally:
        if previous is None:
            os.environ.pop("COLUMNS", None)
        else:
            os.environ["COLUMNS"] = previous
    return "\n".join(sections)


def on_page_markdown(markdown: str, page, config, files) -> str:  # MkDocs calls hooks by keyword
    """Replace the marker with the rendered reference (other pages pass through)."""
    if MARKER not in markdown:
        return markdown
    return markdown.replace(MARKER, render_reference())
