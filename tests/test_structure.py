"""The package's shape: every module sits in a layer package and imports only from its own layer
and the layers below (``LAYERS``); no import circle inside ``drfkit``, counting the imports made
inside functions too (a local import that closes a circle only hides a tie between two modules);
no module over 500 lines; the imports that were stray stay broken; and the longest import chain
does not grow back."""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

from drfkit.util.paths import REPO_ROOT

PACKAGE = REPO_ROOT / "drfkit"


def module_name(path: Path) -> str:
    parts = path.relative_to(REPO_ROOT).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def import_graph() -> dict[str, set[str]]:
    """Module -> the drfkit modules it imports anywhere in its body ("from drfkit.models import
    Monoloco" is an edge to drfkit.models; "from drfkit.study import studies" to drfkit.study.studies)."""
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


def longest_chain(graph: dict[str, set[str]]) -> list[str]:
    """The longest import chain [a, b, ..., z] (a imports b, ...; z imports no drfkit module), for
    a graph without circles; ties are broken by name, so the answer is the same every run."""
    memo: dict[str, list[str]] = {}

    def chain(node: str) -> list[str]:
        if node not in memo:
            memo[node] = [node] + max((chain(n) for n in sorted(graph[node])), key=len, default=[])
        return memo[node]

    return max((chain(n) for n in sorted(graph)), key=len)


MAX_LINES = 500
# modules in the longest chain: 15 before the stray imports were broken and the big modules split,
# 11 after (regime -> report -> claims -> evaluate -> studies -> grid -> train -> models -> models.drf
# -> models.recursion -> filter), 8 since the layers (book.regime_map -> study.regime -> study.ablation
# -> methods.train -> models -> models.drf -> models.recursion -> core.filter)
MAX_CHAIN = 8
# the layers, lowest first: a module of layer L imports only from layers of rank <= L's
LAYERS = {"util": 0, "core": 1, "data": 2, "models": 3, "methods": 4, "study": 5, "report": 6, "book": 7, "cli": 8}
# outside every layer: the package's own __init__ (re-exports load_checkpoint for the notebooks'
# users) and __main__ (``python -m drfkit``: it only calls drfkit.cli)
OUTSIDE_LAYERS = {"drfkit", "drfkit.__main__"}
# (importer, imported): ties that were stray (a score, the ablation's training, notebook start-up)
FORBIDDEN = [("drfkit.methods.diagnostics", "drfkit.methods.gating"), ("drfkit.report.writers", "drfkit.study.ablation"),
             ("drfkit.study.studies", "drfkit.book.runtime")]


def layer_of(module: str) -> str | None:
    """The layer of a module: the package right under drfkit (drfkit.study.claims -> study)."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 and parts[1] in LAYERS else None


def layer_violations(graph: dict[str, set[str]]) -> list[str]:
    """Every import from a layer above the importer's, as 'a (layer) imports b (layer)'."""
    return [f"{a} ({layer_of(a)}) imports {b} ({layer_of(b)})" for a in sorted(graph) if a not in OUTSIDE_LAYERS
            for b in sorted(graph[a]) if b not in OUTSIDE_LAYERS and LAYERS[layer_of(b)] > LAYERS[layer_of(a)]]


def test_layer_checker_known_answer():
    graph = {"drfkit.util.io": set(), "drfkit.study.claims": {"drfkit.util.io"},
             "drfkit.methods.gating": {"drfkit.study.claims"}}
    assert layer_violations(graph) == ["drfkit.methods.gating (methods) imports drfkit.study.claims (study)"]


def test_every_module_sits_in_a_layer():
    graph = import_graph()
    loose = sorted(m for m in graph if m not in OUTSIDE_LAYERS and layer_of(m) is None)
    assert not loose, f"put these in a layer package ({list(LAYERS)}): {loose}"
    assert {layer_of(m) for m in graph} - {None} == set(LAYERS)  # the walk found every layer


def test_no_module_imports_from_a_layer_above_its_own():
    up = layer_violations(import_graph())
    assert not up, "imports against the layer order " + " < ".join(LAYERS) + ":\n" + "\n".join(up)


def test_the_cli_module_and_the_package_import_as_little_as_needed():
    graph = import_graph()
    assert graph["drfkit.__main__"] == {"drfkit.cli"}
    # its commands' modules are imported when they run; the registry's extension loader (light) before them
    assert graph["drfkit.cli"] == {"drfkit.util.registry"}
    assert graph["drfkit"] == {"drfkit.methods.train"}  # load_checkpoint, re-exported


def command_line_code(source: str) -> list[str]:
    """What makes a module a command line: an argparse import or an ``if __name__ == "__main__"``
    block, as 'line: what'."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import) and any(a.name == "argparse" for a in node.names) \
                or isinstance(node, ast.ImportFrom) and node.module == "argparse":
            found.append((node.lineno, "imports argparse"))
        elif isinstance(node, ast.If) and "__name__" in ast.unparse(node.test) and "__main__" in ast.unparse(node.test):
            found.append((node.lineno, "if __name__ == '__main__'"))
    return [f"{line}: {what}" for line, what in sorted(found)]


def test_command_line_finder_known_answer():
    source = "import argparse\ndef f():\n    from argparse import ArgumentParser\nif __name__ == '__main__':\n    f()\n"
    assert command_line_code(source) == ["1: imports argparse", "3: imports argparse", "4: if __name__ == '__main__'"]
    assert command_line_code("import os\nname = __name__\n") == []


def test_every_command_line_lives_in_drfkit_cli():
    """One home for the command lines: argparse and ``__main__`` blocks only under drfkit/cli/ (and
    ``python -m drfkit`` itself); the library below takes explicit arguments."""
    outside = [f"{module_name(p)} {hit}" for p in sorted(PACKAGE.rglob("*.py"))
               if layer_of(module_name(p)) != "cli" and module_name(p) != "drfkit.__main__"
               for hit in command_line_code(p.read_text(encoding="utf-8"))]
    assert not outside, "move these into drfkit/cli/: " + "; ".join(outside)
    assert command_line_code((PACKAGE / "cli" / "__init__.py").read_text(encoding="utf-8"))  # the finder sees the home


def test_cycle_finder_sees_a_circle_and_accepts_a_tree():
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert find_cycle({"a": {"b", "c"}, "b": {"c"}, "c": set()}) is None


def test_no_import_circle_inside_drfkit():
    graph = import_graph()
    assert "drfkit.models.parts" in graph and "drfkit.study.studies" in graph  # the walk found the package
    cycle = find_cycle(graph)
    assert cycle is None, "import circle: " + " -> ".join(cycle)


def test_no_module_is_over_500_lines():
    lengths = {p.relative_to(REPO_ROOT).as_posix(): len(p.read_text(encoding="utf-8").splitlines())
               for p in PACKAGE.rglob("*.py")}
    assert len(lengths) > 30  # the walk found the package
    too_long = {path: n for path, n in sorted(lengths.items()) if n > MAX_LINES}
    assert not too_long, f"split these along their concepts (at most {MAX_LINES} lines each): {too_long}"


def test_stray_imports_stay_broken():
    graph = import_graph()
    assert all(a in graph and b in graph for a, b in FORBIDDEN)
    back = [f"{a} imports {b}" for a, b in FORBIDDEN if b in graph[a]]
    assert not back, back


def test_chain_finder_known_answer():
    assert longest_chain({"a": {"b", "c"}, "b": {"c"}, "c": set(), "d": {"a"}}) == ["d", "a", "b", "c"]
    assert longest_chain({"x": set()}) == ["x"]


def test_longest_import_chain_does_not_grow():
    graph = import_graph()
    assert find_cycle(graph) is None
    # the library's chain: a command of drfkit.cli sits on top of it and adds one module, by design
    library = {m: {n for n in deps if layer_of(n) != "cli"} for m, deps in graph.items()
               if layer_of(m) != "cli" and m not in OUTSIDE_LAYERS}
    assert len(longest_chain(graph)) <= MAX_CHAIN + 1
    chain = longest_chain(library)
    print(f"longest import chain ({len(chain)} modules): " + " -> ".join(chain))
    assert len(chain) <= MAX_CHAIN, ("the longest import chain grew to " + str(len(chain)) + " modules: "
                                     + " -> ".join(chain))


def test_every_registered_study_is_wired_end_to_end():
    """Each entry of drfkit.study.registry holds callables for its data and runs, profile keys the schema
    knows (and its training notebook accepts), a training notebook, and model kinds that build."""
    from drfkit.study import studies
    from drfkit.models import MODEL_CLASSES
    from drfkit.study.params import NOTEBOOKS
    from drfkit.study.schema import PATHS, SPECS, flat_name
    from drfkit.data.noise import NOISE_KINDS, Noise
    from drfkit.study.claims.efficiency import GATING_CLAIMS
    from drfkit.study.registry import STUDIES

    for name, s in STUDIES.items():
        assert all(callable(f) for f in (s.data, s.data_key, s.model_options, s.train_config, s.fresh_training)), name
        assert "paper" in s.all_protocols, name
        assert s.training_notebook in NOTEBOOKS, name
        keys = [s.models_key, s.train_level_key, s.eval_levels_key, s.sweep_key, s.protocols_key]
        names = [flat_name(s.section, k) for k in keys]  # raises for a key the schema's section lacks
        assert all(n in NOTEBOOKS[s.training_notebook] for n in names[:2]), name
        assert set(s.kinds) <= set(MODEL_CLASSES), name
        assert studies.TRAINING_NOTEBOOK[name] == s.training_notebook
        assert s.noise_kind in NOISE_KINDS and s.noise(0.1) == Noise(s.noise_kind, 0.1), name
        assert s.gating_claim in ("", *GATING_CLAIMS), name
    # a registry-bounded list of a study's section (its models, its protocols) is bounded by a study that reads it
    for key, spec in SPECS.items():
        if spec.registry and spec.registry != "*":
            assert any(s.section == PATHS[key][0] for s in STUDIES.values()), key


def profile_reads(source: str, names: set[str]) -> list[str]:
    """Every ``P.<name>`` in ``source`` where ``name`` is a field of the typed profile (a section such as
    ``pendulum`` or a top-level parameter such as ``seeds``): how the book reads its profile ``P`` (a
    covariance called P has ``P.shape``, no profile names)."""
    return [f"{node.lineno}: P.{node.attr}" for node in ast.walk(ast.parse(source))
            if isinstance(node, ast.Attribute) and node.attr in names and isinstance(node.value, ast.Name)
            and node.value.id == "P"]


def test_profile_reader_known_answer():
    source = "def f(P, z, p):\n    return P.pendulum.lr + z.pendulum.lr + P.shape[0] + p.uncertainty.n_samples\n"
    assert profile_reads(source, {"pendulum", "uncertainty"}) == ["2: P.pendulum"]


def test_nothing_below_the_study_layer_reads_the_profile():
    """Methods, models, data, core and util take explicit arguments: no module there reads a
    profile parameter off the profile (``P.pendulum.lr``); the study and book layers are its readers."""
    import dataclasses

    from drfkit.study.profile import Profile

    below = [p for p in PACKAGE.rglob("*.py") if layer_of(module_name(p)) in
             {name for name, rank in LAYERS.items() if rank < LAYERS["study"]}]
    assert len(below) > 20, "the layers below the study layer were not found"
    reads = [f"{module_name(p)}:{r}" for p in below for r in profile_reads(p.read_text(encoding="utf-8"), {f.name for f in dataclasses.fields(Profile)})]
    assert not reads, "the profile read below the study layer: " + "; ".join(reads)


def test_the_registry_says_which_levels_and_models_a_claim_sees():
    from drfkit.study.profile import build_profile
    from drfkit.study.registry import STUDIES

    P = build_profile(dict(pend_eval_max_noise=[0.5, 0.75], pend_train_max_noise=0.5, pend_models=["drf", "lstm"],
                           ped_eval_p=[0.01, 0.025, 0.05], ped_train_p=0.01, ped_models=["monoloco", "drf"]), "a test")
    assert STUDIES["pendulum"].shifted_levels(P) == [0.75] and STUDIES["pendulum"].baselines(P) == ["lstm"]
    assert STUDIES["pedestrians"].shifted_levels(P) == [0.025, 0.05] and STUDIES["pedestrians"].baselines(P) == ["monoloco"]


PROCESS_WORDS = ("subprocess.", "papermill", "execute_notebook", "LocalCluster", "Popen")


def test_every_test_that_starts_a_process_is_marked_slow():
    # the edit loop (pytest -m "not slow", README) stays fast only if new process-starting tests are marked
    unmarked = []
    for path in sorted((REPO_ROOT / "tests").glob("test_*.py")):
        src = path.read_text(encoding="utf-8")
        module_slow = "pytestmark = pytest.mark.slow" in src
        for node in ast.parse(src).body:
            if isinstance(node, ast.FunctionDef) and node.name.startswith("test_"):
                body = ast.get_source_segment(src, node)
                marked = module_slow or any("slow" in ast.unparse(d) for d in node.decorator_list)
                if not marked and node.name != "test_every_test_that_starts_a_process_is_marked_slow" \
                        and any(word in body for word in PROCESS_WORDS):
                    unmarked.append(f"{path.name}::{node.name}")
    assert not unmarked, "add @pytest.mark.slow to: " + ", ".join(unmarked)


def test_no_private_name_is_imported_from_another_package():
    # a leading underscore says "this package's own": another package reaching for it ties the two
    crossing = []
    for path in PACKAGE.rglob("*.py"):
        importer = module_name(path)
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("drfkit."):
                if node.module.split(".")[:2] == importer.split(".")[:2]:
                    continue
                crossing += [f"{importer} imports {node.module}.{a.name}" for a in node.names
                             if a.name.startswith("_") and not a.name.startswith("__")]
    assert not crossing, "\n".join(crossing)


def test_the_package_face_is_light_importing_drfkit_or_its_util_or_the_command_list_loads_no_torch():
    """``import drfkit``, ``drfkit.util`` (and its paths, registry), ``drfkit.cli`` and ``python -m drfkit --help``
    load neither torch nor numpy nor pandas: a command's help and a path lookup answer at once."""
    import subprocess
    import sys

    code = ("import sys, drfkit, drfkit.util, drfkit.util.paths, drfkit.util.registry, drfkit.cli\n"
            "from drfkit.cli import main\n"
            "import contextlib, io\n"
            "with contextlib.redirect_stdout(io.StringIO()):\n"
            "    main(['--help'])\n"
            "heavy = sorted(m for m in ('torch', 'numpy', 'pandas') if m in sys.modules)\n"
            "print(','.join(heavy))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "", f"the light face loads {out.stdout.strip()}"
    import drfkit
    assert callable(drfkit.load_checkpoint)            # still there, on first use
    with pytest.raises(AttributeError, match="no attribute 'nope'"):
        drfkit.nope  # noqa: B018
