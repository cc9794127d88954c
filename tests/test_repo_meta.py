"""The README's newcomer commands stay true: CI runs exactly the README's test command."""

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def readme_commands():
    text = (ROOT / "README.md").read_text()
    return re.findall(r"```bash\n(.+?)\n```", text)


def test_readme_opens_with_the_two_newcomer_commands():
    commands = readme_commands()
    assert len(commands) >= 2
    run_cmd, test_cmd = commands[0], commands[1]
    assert "fdi run" in run_cmd and "venv" in run_cmd
    assert "pytest" in test_cmd and "venv" in test_cmd


def test_ci_runs_exactly_the_readme_test_command():
    test_cmd = readme_commands()[1]
    ci_lines = (ROOT / ".ci" / "run").read_text().splitlines()
    assert test_cmd in ci_lines


def test_version_has_one_source_and_the_changelog_names_it():
    import subprocess
    import sys

    import fdi_daemon

    pyproject = re.search(r'^version = "(.+)"$', (ROOT / "pyproject.toml").read_text(), re.M)[1]
    printed = subprocess.run(
        [sys.executable, "-m", "fdi_daemon", "--version"],
        capture_output=True,
        text=True,
        check=True,
    ).stdout.split()
    assert fdi_daemon.__version__ == pyproject
    assert printed == ["fdi", pyproject]
    changelog = (ROOT / "CHANGELOG.md").read_text()
    assert "## Unreleased" in changelog and f"## {pyproject}" in changelog
