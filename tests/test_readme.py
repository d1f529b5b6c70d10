"""The README's filter example runs and does what it says: filtering beats the raw observations."""
import re

import torch

from drfkit.paths import REPO_ROOT


def test_readme_filter_example_runs_and_filters(capsys):
    text = (REPO_ROOT / "README.md").read_text()
    code = re.search(r"### The filter on its own\n\n```python\n(.*?)```", text, re.S).group(1)
    assert len(code.strip().splitlines()) <= 20
    namespace: dict = {}
    exec(compile(code, "README.md", "exec"), namespace)
    errors = torch.stack(namespace["errors"])[10:].mean(0)
    r = namespace["r"]
    # the filtered error is below the observation noise's mean absolute value sqrt(2 r / pi)
    assert (errors < (2 * r / torch.pi).sqrt()).all()
    assert "gain diag" in capsys.readouterr().out
