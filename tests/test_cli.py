"""``python -m drfkit <command>``: one entry point for every command the README and the Makefile
name; each is a function of one module of ``drfkit.cli``."""
from __future__ import annotations

import re
import subprocess
import sys

import pytest

from drfkit.cli import COMMANDS, command, main
from drfkit.util.paths import REPO_ROOT


@pytest.mark.parametrize("name", sorted(COMMANDS))
def test_every_command_has_its_function_and_help(name, capsys):
    assert callable(command(name))
    with pytest.raises(SystemExit) as exc:
        main([name, "--help"])
    assert exc.value.code == 0
    assert f"python -m drfkit {name}" in capsys.readouterr().out  # argparse's usage names the command


def test_help_lists_every_command_on_one_line(capsys):
    assert main(["--help"]) == 0
    out = capsys.readouterr().out
    assert all(re.search(rf"^  {name} +\S", out, re.M) for name in COMMANDS)
    assert main([]) == 2 and main(["no-such-command"]) == 2
    with pytest.raises(KeyError, match="unknown command 'nope'"):
        command("nope")


def test_every_command_the_docs_name_exists():
    """Every ``python -m drfkit <command>`` in the README, the Makefile and docs/ is one of COMMANDS."""
    texts = [REPO_ROOT / "README.md", REPO_ROOT / "Makefile", *sorted((REPO_ROOT / "docs").glob("*.md"))]
    named = {m for p in texts for m in re.findall(r"-m drfkit ([a-z][\w-]*)", p.read_text(encoding="utf-8"))}
    assert named and named <= set(COMMANDS), named - set(COMMANDS)
    assert not [p.name for p in texts if re.search(r"-m drfkit\.\w", p.read_text(encoding="utf-8"))]


@pytest.mark.slow
def test_python_dash_m_drfkit_runs():
    proc = subprocess.run([sys.executable, "-m", "drfkit", "--help"], capture_output=True, text=True, cwd=REPO_ROOT,
                          timeout=120)
    assert proc.returncode == 0 and "reproduce" in proc.stdout


def test_every_public_function_of_the_cli_modules_is_a_listed_command():
    """A command is its function in the module COMMANDS names and one line there: none is missing
    from the list, none sits in another module."""
    import importlib
    import inspect

    for module in sorted({m for m, _ in COMMANDS.values()}):
        mod = importlib.import_module(f"drfkit.cli.{module}")
        public = {n for n, f in inspect.getmembers(mod, inspect.isfunction)
                  if f.__module__ == mod.__name__ and not n.startswith("_")}
        assert public == {n for n, (m, _) in COMMANDS.items() if m == module}, module
