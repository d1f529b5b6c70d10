"""The package's shape: no import circle inside ``drfkit``, counting the imports made inside
functions too (a local import that closes a circle only hides a tie between two modules)."""
from __future__ import annotations

import ast
from pathlib import Path

from drfkit.paths import REPO_ROOT

PACKAGE = REPO_ROOT / "drfkit"


def module_name(path: Path) -> str:
    parts = path.relative_to(REPO_ROOT).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def import_graph() -> dict[str, set[str]]:
    """Module -> the drfkit modules it imports anywhere in its body ("from drfkit.models import
    Monoloco" is an edge to drfkit.models; "from drfkit import studies" to drfkit.studies)."""
    modules = {module_name(p): p for p in PACKAGE.rglob("*.py")}
    graph = {}
    for name, path in modules.items():
        targets = set()
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Import):
                targets |= {a.name for a in node.names}
            elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                targets |= {f"{node.module}.{a.name}" if f"{node.module}.{a.name}" in modules else node.module
                            for a in node.names}
        graph[name] = {t for t in targets if t in modules and t != name}
    return graph


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One import circle as [a, b, ..., a], or None (depth-first search, three colours)."""
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = 1
        stack.append(node)
        for nxt in sorted(graph[node]):
            if state.get(nxt) == 1:
                return stack[stack.index(nxt):] + [nxt]
            if nxt not in state and (found := visit(nxt)):
                return found
        stack.pop()
        state[node] = 2
        return None

    for node in sorted(graph):
        if node not in state and (found := visit(node)):
            return found
    return None


def test_cycle_finder_sees_a_circle_and_accepts_a_tree():
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert find_cycle({"a": {"b", "c"}, "b": {"c"}, "c": set()}) is None


def test_no_import_circle_inside_drfkit():
    graph = import_graph()
    assert "drfkit.models.parts" in graph and "drfkit.studies" in graph  # the walk found the package
    cycle = find_cycle(graph)
    assert cycle is None, "import circle: " + " -> ".join(cycle)


def test_every_registered_study_is_wired_end_to_end():
    """Each entry of drfkit.registry names data functions that exist, profile keys the schema
    knows (and its training notebook accepts), a training notebook, and model kinds that build."""
    from drfkit import studies
    from drfkit.models import MODEL_CLASSES
    from drfkit.params import NOTEBOOKS, SPECS
    from drfkit.data.noise import NOISE_KINDS, Noise
    from drfkit.registry import STUDIES

    for name, s in STUDIES.items():
        assert callable(getattr(studies, s.data)) and callable(getattr(studies, s.data_key)), name
        assert s.training_notebook in NOTEBOOKS, name
        keys = [s.models_key, s.train_level_key, s.eval_levels_key, s.sweep_key] + ([s.protocols_key] if s.protocols_key else [])
        assert all(k in SPECS for k in keys), (name, [k for k in keys if k not in SPECS])
        assert all(k in NOTEBOOKS[s.training_notebook] for k in (s.models_key, s.train_level_key)), name
        assert set(s.kinds) <= set(MODEL_CLASSES), name
        assert studies.TRAINING_NOTEBOOK[name] == s.training_notebook
        assert s.noise_kind in NOISE_KINDS and s.noise(0.1) == Noise(s.noise_kind, 0.1), name
