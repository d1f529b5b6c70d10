"""Build notebooks/NN_*.ipynb from their percent-format sources in notebooks/src/.

The sources are plain Python (reviewable diffs); the .ipynb files are what papermill and
nbval run. ``--execute`` runs each notebook with its defaults (the quick profile) and
stores the outputs, which strict nbval then compares against.

The sources are jupytext's percent format (``# %%`` a code cell, ``# %% [markdown]`` a
markdown cell, ``# %% tags=["..."]`` tags), read by jupytext. The body of the cell tagged
``parameters`` is generated from ``params/quick.yaml`` (one place for the defaults).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import nbformat

ROOT = Path(__file__).resolve().parents[1]
SRC, OUT = ROOT / "notebooks" / "src", ROOT / "notebooks"


def parameters_cell(notebook: str) -> str:
    """The notebook's parameters, with the quick profile's values (what nbval runs)."""
    sys.path.insert(0, str(ROOT))
    from drfkit.study.params import NOTEBOOKS, PATHS, SPECS, allowed_text, load_profile

    quick = load_profile("quick")
    lines = ["# Defaults = the quick profile (params/quick.yaml); papermill overrides them.",
             "# Each name's place in a profile's sections is in brackets."]
    for key in NOTEBOOKS[notebook]:
        lines += [f"# {key} [{'.'.join(PATHS[key])}]: {allowed_text(key)}", f"{key} = {quick[key]!r}"]
    return "\n".join(lines)


def parse(text: str, notebook: str) -> nbformat.NotebookNode:
    """The notebook of a percent-format source (read by jupytext), its parameters cell filled in."""
    import jupytext

    nb = jupytext.reads(text, fmt="py:percent")
    nb.metadata = nbformat.NotebookNode(
        kernelspec={"name": "python3", "display_name": "Python 3", "language": "python"},
        language_info={"name": "python"})
    for i, cell in enumerate(nb.cells):
        tags = cell.metadata.get("tags", [])
        cell.metadata = nbformat.NotebookNode({"tags": tags} if tags else {})  # not jupytext's layout hints
        if "parameters" in tags:
            cell.source = parameters_cell(notebook)
        cell["id"] = f"cell-{i:02d}"  # stable ids keep diffs small
    return nb


def execute(path: Path, timeout: int = 1800) -> None:
    from nbclient import NotebookClient

    from drfkit.book.pipeline import ipc_kernels  # the kernel over IPC, as the pipeline's

    nb = nbformat.read(path, as_version=4)
    with ipc_kernels() as config:
        NotebookClient(nb, timeout=timeout, kernel_name="python3", config=config,
                       resources={"metadata": {"path": str(OUT)}}).execute()
    for cell in nb.cells:  # execution counts are noise in diffs; nbval ignores them
        cell.metadata.pop("execution", None)
    nbformat.write(nb, path)


def _same_names(cell, old_cells, i: int) -> bool:
    """Whether ``cell`` defines exactly what the old notebook's cell ``i`` defined (same values)."""
    if i >= len(old_cells) or old_cells[i].cell_type != "code" or old_cells[i].outputs:
        return False
    defined = [{}, {}]
    for ns, source in zip(defined, (cell.source, old_cells[i].source)):
        exec(source, ns)
        ns.pop("__builtins__", None)
    # repr, not ==: 1, 1.0 and True are equal in Python but are different parameter values
    return {k: repr(v) for k, v in defined[0].items()} == {k: repr(v) for k, v in defined[1].items()}


def keep_outputs(new: nbformat.NotebookNode, target: Path) -> int:
    """Copy the stored outputs of ``target`` into ``new`` for every code cell whose source did not
    change (matched by position and source); returns how many code cells had to lose theirs.
    For edits of markdown cells, which need no re-execution. The ``parameters`` cell is generated and
    defines names only (no outputs): a change to its comments or layout loses nothing."""
    if not target.exists():
        return sum(c.cell_type == "code" for c in new.cells)
    old = nbformat.read(target, as_version=4)
    new.metadata = old.metadata  # the execution's metadata (widget state, language version) goes with its outputs
    old_code = {(i, c.source): c for i, c in enumerate(old.cells) if c.cell_type == "code"}
    missing = 0
    for i, cell in enumerate(new.cells):
        if cell.cell_type != "code":
            continue
        match = old_code.get((i, cell.source))
        if match is None and "parameters" in cell.metadata.get("tags", []) and _same_names(cell, old.cells, i):
            cell.execution_count = old.cells[i].execution_count
            continue
        if match is None:
            missing += 1
        else:
            cell.outputs, cell.execution_count = match.outputs, match.execution_count
    return missing


def _code_sources(nb: nbformat.NotebookNode) -> list[str]:
    """The sources of the code cells, without a parameters cell (the pipeline's papermill injects its own)."""
    skip = {"parameters", "injected-parameters"}
    return [c.source for c in nb.cells if c.cell_type == "code" and not skip & set(c.metadata.get("tags", []))]


def sync_markdown(new: nbformat.NotebookNode, target: Path) -> int:
    """Give the executed notebook ``target`` (a profile's ``results/<profile>/executed/``) the markdown cells of
    ``new``, in order, its code cells and outputs untouched; returns how many markdown cells changed. For a
    prose edit made after a profile's run, which changes no number. Raises ValueError when the two differ in
    anything but their markdown (the count of markdown cells, or a code cell's source): that needs a rerun."""
    old = nbformat.read(target, as_version=4)
    old_md = [c for c in old.cells if c.cell_type == "markdown"]
    new_md = [c for c in new.cells if c.cell_type == "markdown"]
    if len(old_md) != len(new_md) or _code_sources(old) != _code_sources(new):
        raise ValueError(f"{target}: its code or the number of its markdown cells differs from the source's; "
                         "rerun the notebook (make reproduce) instead of syncing its prose")
    changed = 0
    for cell, source in zip(old_md, new_md):
        if cell.source != source.source:
            cell.source, changed = source.source, changed + 1
    if changed:
        nbformat.write(old, target)
    return changed


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("names", nargs="*", help="source stems to build (default: all)")
    ap.add_argument("--execute", action="store_true", help="run and store outputs")
    ap.add_argument("--keep-outputs", action="store_true",
                    help="keep the stored outputs of code cells whose source is unchanged (after markdown edits); "
                         "fails if a code cell changed, which needs --execute")
    ap.add_argument("--sync-markdown", metavar="FOLDER", type=Path,
                    help="give the executed notebooks in FOLDER (results/<profile>/executed) the sources' markdown "
                         "cells, outputs untouched; fails where a code cell differs (that needs a rerun)")
    args = ap.parse_args()
    sources = sorted(SRC.glob("*.py"))
    if args.names:
        sources = [s for s in sources if any(s.stem.startswith(n) for n in args.names)]
    if args.sync_markdown:
        for src in sources:
            target = args.sync_markdown / f"{src.stem}.ipynb"
            if target.exists():
                try:
                    changed = sync_markdown(parse(src.read_text(), src.stem), target)
                except ValueError as exc:
                    print(exc, file=sys.stderr)
                    return 1
                print(f"{target}: {changed} markdown cell(s) synced", flush=True)
        return 0
    for src in sources:
        target = OUT / f"{src.stem}.ipynb"
        nb = parse(src.read_text(), src.stem)
        if args.keep_outputs and not args.execute:
            changed = keep_outputs(nb, target)
            if changed:
                print(f"{target.relative_to(ROOT)}: {changed} code cell(s) changed; rebuild it with --execute",
                      file=sys.stderr)
                return 1
        nbformat.write(nb, target)
        print(f"built {target.relative_to(ROOT)}", flush=True)
        if args.execute:
            execute(target)
            print(f"executed {target.relative_to(ROOT)}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
