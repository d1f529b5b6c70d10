"""``python -m drfkit <command>``: one entry point for every command the README and the Makefile
name; each dispatches to its module's ``main(argv)``."""
from __future__ import annotations

import importlib
import re
import subprocess
import sys

import pytest

from drfkit.__main__ import COMMANDS, main
from drfkit.util.paths import REPO_ROOT


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_every_command_dispatches_to_its_main(command, capsys):
    assert callable(importlib.import_module(COMMANDS[command][0]).main)
    with pytest.raises(SystemExit) as exc:
        main([command, "--help"])
    assert exc.value.code == 0
    assert f"python -m drfkit {command}" in capsys.readouterr().out  # argparse's usage names the command


def test_help_lists_every_command_on_one_line(capsys):
    assert main(["--help"]) == 0
    out = capsys.readouterr().out
    assert all(re.search(rf"^  {name} +\S", out, re.M) for name in COMMANDS)
    assert main([]) == 2 and main(["no-such-command"]) == 2


def test_every_command_the_docs_name_exists():
    """Every ``python -m drfkit <command>`` in the README, the Makefile and docs/ is one of COMMANDS."""
    texts = [REPO_ROOT / "README.md", REPO_ROOT / "Makefile", *sorted((REPO_ROOT / "docs").glob("*.md"))]
    named = {m for p in texts for m in re.findall(r"-m drfkit ([\w-]+)", p.read_text(encoding="utf-8"))}
    assert named and named <= set(COMMANDS), named - set(COMMANDS)
    assert not [p.name for p in texts if re.search(r"-m drfkit\.\w", p.read_text(encoding="utf-8"))]


@pytest.mark.slow
def test_python_dash_m_drfkit_runs():
    proc = subprocess.run([sys.executable, "-m", "drfkit", "--help"], capture_output=True, text=True, cwd=REPO_ROOT,
                          timeout=120)
    assert proc.returncode == 0 and "reproduce" in proc.stdout
