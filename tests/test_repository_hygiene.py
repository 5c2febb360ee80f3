"""The tracked files hold facts, not the history of how they were written, and no machine paths.

Over every tracked text file (``git ls-files``; binaries and this file skipped) the test fails
on

* a development session number ("session 31", "sessions 22-25"),
* an issue number ("issue 14", "issue #9", "issue9"),
* an absolute path of the machine the test runs on: the checkout's absolute path and its
  parent, the home folder, the temporary folder, and the top-level folder holding the
  checkout (``/work/`` on a machine whose checkout is ``/work/main``), all found at run time.

History belongs in ``CHANGELOG.md`` and git; commands use paths relative to the repository or
a ``$DATA`` placeholder for the data folder.
"""

from __future__ import annotations

import re
import subprocess
import tempfile
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
THIS = Path(__file__).resolve().relative_to(REPO).as_posix()

SESSION = re.compile(r"\bsessions?\s*#?\s*\d+", re.IGNORECASE)
ISSUE = re.compile(r"\bissues?\s*#?\s*\d+", re.IGNORECASE)

# Tracked files allowed to hold a machine path, each with the reason (none today: a test that
# needs a path builds it at run time from tmp_path or Path.home()).
PATH_ALLOWED: dict[str, str] = {}


def tracked_text_files() -> list[Path]:
    """The tracked files of the checkout that decode as UTF-8 text (this test excluded)."""
    try:
        listing = subprocess.run(
            ["git", "ls-files", "-z"], cwd=REPO, capture_output=True, check=True
        ).stdout
    except (OSError, subprocess.CalledProcessError):
        pytest.skip("not a git checkout (or git is not installed)")
    files = []
    for name in listing.decode().split("\0"):
        path = REPO / name
        if not name or name == THIS or not path.is_file():
            continue
        data = path.read_bytes()
        if b"\0" in data[:8192]:
            continue  # binary
        try:
            data.decode("utf-8")
        except UnicodeDecodeError:
            continue
        files.append(path)
    return files


def machine_paths() -> list[str]:
    """Absolute folders of this machine that no tracked file may name, longest first.

    The checkout, its parent, the folder under the root that holds the checkout (``/work``
    for ``/work/main``), the home folder and the temporary folder; the root itself and
    one-letter folders are left out (they would match any path-like text).
    """
    candidates = {
        REPO,
        REPO.parent,
        Path(*REPO.parts[:2]) if len(REPO.parts) > 2 else REPO,
        Path.home(),
        Path(tempfile.gettempdir()).resolve(),
    }
    folders = {str(p) for p in candidates if len(p.parts) > 1 and len(p.parts[1]) > 1}
    return sorted(folders, key=len, reverse=True)


def path_pattern(folders: list[str]) -> re.Pattern[str]:
    """A folder named as an absolute path: preceded by no path character, followed by ``/``
    or the end of the name (``/work/x`` matches ``/work``; ``/workshop`` and ``a/work/x`` do
    not)."""
    alternatives = "|".join(re.escape(f) for f in folders)
    return re.compile(rf"(?<![\w./~-])(?:{alternatives})(?=/|\b(?![\w.-]))")


def violations(
    files: list[Path], patterns: dict[str, re.Pattern[str]], allowed: dict[str, str]
) -> list[str]:
    """``path:line: kind: text`` of every match outside the allowed files."""
    found = []
    for path in files:
        name = path.relative_to(REPO).as_posix()
        text = path.read_text(encoding="utf-8")
        for kind, pattern in patterns.items():
            if kind == "machine path" and name in allowed:
                continue
            for match in pattern.finditer(text):
                line = text.count("\n", 0, match.start()) + 1
                found.append(f"{name}:{line}: {kind}: {match.group(0)!r}")
    return found


def test_path_pattern_matches_the_folder_and_its_children_only() -> None:
    pattern = path_pattern(["/work"])
    assert pattern.search("see /work/data/rdv3000")
    assert pattern.search('"/work"')
    assert not pattern.search("/workshop/x")
    assert not pattern.search("docs/work/x")
    assert not pattern.search("./work/x")


def test_session_and_issue_patterns_match_numbers_only() -> None:
    assert SESSION.search("measured in Session 31")
    assert SESSION.search("sessions 22")
    assert ISSUE.search("see issue #9") and ISSUE.search("issue9") and ISSUE.search("Issue 14")
    assert not SESSION.search("a training session of the model")
    assert not ISSUE.search("an open issue with the solver")


def test_tracked_files_name_no_session_or_issue_number() -> None:
    found = violations(tracked_text_files(), {"session": SESSION, "issue": ISSUE}, {})
    assert not found, "history belongs in CHANGELOG.md:\n" + "\n".join(found[:50])


def test_tracked_files_hold_no_absolute_path_of_this_machine() -> None:
    pattern = path_pattern(machine_paths())
    found = violations(tracked_text_files(), {"machine path": pattern}, PATH_ALLOWED)
    assert not found, "use a path relative to the repository or $DATA:\n" + "\n".join(found[:50])


FACADES = ("scpformer.pdg6dof", "scpformer.rendezvous", "scpformer.robust_rendezvous")


def test_the_api_reference_renders_every_family_facade() -> None:
    """Each family's public module is rendered whole (``::: scpformer.<family>``), so every
    function it exports (``solve``, ``sample_instances``, ...) is in the API reference."""
    import importlib
    import inspect

    pages = "\n".join(p.read_text(encoding="utf-8") for p in (REPO / "docs" / "api").glob("*.md"))
    directives = set(re.findall(r"^::: ([\w.]+)\s*$", pages, flags=re.MULTILINE))
    for name in FACADES:
        assert name in directives, f"docs/api/ has no '::: {name}'"
        module = importlib.import_module(name)
        functions = [n for n in module.__all__ if inspect.isfunction(getattr(module, n))]
        assert "solve" in functions and "sample_instances" in functions, (name, functions)


def test_the_changelog_has_a_dated_entry_for_the_current_version() -> None:
    import tomllib

    version = tomllib.loads((REPO / "pyproject.toml").read_text(encoding="utf-8"))["project"][
        "version"
    ]
    changelog = (REPO / "CHANGELOG.md").read_text(encoding="utf-8")
    entries = re.findall(r"^## (\d+\.\d+\.\d+) - (\d{4}-\d{2}-\d{2})$", changelog, re.MULTILINE)
    assert entries, "CHANGELOG.md has no '## X.Y.Z - YYYY-MM-DD' entry"
    assert entries[0][0] == version, f"the newest entry is {entries[0][0]}, pyproject {version}"
