"""Parameter validation: the schema, the YAML profiles and the notebooks agree, and a wrong
parameter fails fast with a message naming the key, the notebook and the allowed values."""
import json
import subprocess
import sys

import pytest
import yaml

from drfkit.study.params import (NOTEBOOKS, PATHS, SPECS, ParameterError, load_profile, nest_profile, notebook_params,
                           parse_overrides, validate, write_profile)
from drfkit.util.paths import NOTEBOOKS_DIR, PARAMS_DIR, REPO_ROOT


def quick_subset(nb):
    return {k: load_profile("quick")[k] for k in NOTEBOOKS[nb]}


@pytest.mark.parametrize("profile", ["quick", "paper"])
def test_profiles_are_complete_and_valid(profile):
    values = load_profile(profile)
    assert set(values) == set(SPECS)  # every parameter set explicitly, none unknown
    for nb in NOTEBOOKS:
        notebook_params(nb, values)


def test_paper_profile_is_paper_scale():
    paper = load_profile("paper")
    assert paper["pend_train_sequences"] == 2000 and paper["pend_test_sequences"] == 1000
    assert paper["pend_seq_len"] == 75 and paper["pend_epochs"] == 200 and paper["pend_lr"] == 1e-4
    assert len(paper["seeds"]) >= 3
    assert paper["pend_eval_max_noise"] == [0.5, 0.75] and paper["ped_eval_p"] == [0.01, 0.025, 0.05]
    assert paper["pend_patience"] == 0  # no early stop: the paper's 200 epochs


def test_committed_paper_pendulum_runs_trained_every_epoch():
    import pandas as pd

    from drfkit.util.paths import REPO_ROOT

    paper = load_profile("paper")
    table = pd.read_csv(REPO_ROOT / "results/paper/tables/pendulum_model_selection.csv")
    runs = {(m, s) for m in paper["pend_models"] for s in paper["seeds"]}
    assert set(zip(table["model"], table["seed"])) == runs
    assert (table["epochs"] == paper["pend_epochs"]).all(), table[["model", "seed", "epochs"]]


def _parameters_cells(nb_path):
    nb = json.loads(nb_path.read_text())
    return [c for c in nb["cells"] if "parameters" in c.get("metadata", {}).get("tags", [])]


@pytest.mark.parametrize("name", list(NOTEBOOKS))
def test_notebook_defaults_are_the_quick_profile(name):
    path = NOTEBOOKS_DIR / f"{name}.ipynb"
    cells = _parameters_cells(path)
    assert len(cells) == 1, f"{path} needs exactly one cell tagged 'parameters'"
    namespace: dict = {}
    exec("".join(cells[0]["source"]), namespace)
    namespace.pop("__builtins__")
    assert namespace == quick_subset(name)


def test_unknown_key_names_key_notebook_and_allowed():
    values = quick_subset("01_pendulum_training") | {"pend_epoch": 3}
    with pytest.raises(ParameterError) as err:
        validate("01_pendulum_training", values)
    msg = str(err.value)
    assert "pend_epoch" in msg and "01_pendulum_training" in msg and "pend_epochs" in msg


@pytest.mark.parametrize("key, value, fragment", [
    ("pend_epochs", "10", "must be an integer"),
    ("pend_epochs", 2.5, "must be an integer"),
    ("pend_epochs", True, "must be an integer"),
    ("pend_epochs", 0, "out of range"),
    ("pend_train_max_noise", -0.1, "out of range"),
    ("pend_train_max_noise", 1.5, "out of range"),
    ("pend_train_sequences", 0, "out of range"),
    ("n_samples", 0, "out of range"),
    ("seeds", [], "out of range"),
    ("seeds", [1, 1], "out of range"),
    ("pend_models", ["drf", "kalmannet"], "out of range"),
    ("dropout_rates", [0.1, 1.0], "out of range"),
    ("device", "tpu", "out of range"),
    ("pend_lr", float("nan"), "finite number"),
])
def test_wrong_type_or_range_names_the_key(key, value, fragment):
    values = quick_subset("01_pendulum_training") | {key: value}
    with pytest.raises(ParameterError) as err:
        validate("01_pendulum_training", values)
    assert key in str(err.value) and fragment in str(err.value) and "allowed" in str(err.value)
    assert f"[{'.'.join(PATHS[key])}]" in str(err.value)  # where the key sits in a profile


@pytest.mark.parametrize("value", [[], ["pendulum", "pendulum"], ["nuscenes"], "pendulum"])
def test_eval_studies_must_be_a_subset_of_the_studies(value):
    values = quick_subset("04_ood_noise_evaluation") | {"eval_studies": value}
    with pytest.raises(ParameterError, match="eval_studies"):
        validate("04_ood_noise_evaluation", values)
    ok = validate("06_competency_gating", quick_subset("06_competency_gating") | {"eval_studies": ["pedestrians"]})
    assert ok.evaluation.studies == ["pedestrians"]


def test_missing_parameter_is_reported():
    values = quick_subset("05_timing")
    del values["n_samples"]
    with pytest.raises(ParameterError, match="n_samples"):
        validate("05_timing", values)


def test_bad_detector_config_is_rejected():
    values = quick_subset("03_nuscenes_training") | {"sim_detector": {"no_such_field": 1}}
    with pytest.raises(ParameterError, match="sim_detector"):
        validate("03_nuscenes_training", values)


@pytest.mark.slow
def test_yaml_with_unknown_key_fails_before_any_notebook_runs(tmp_path):
    bad = yaml.safe_load((PARAMS_DIR / "quick.yaml").read_text())
    bad["pendulum"]["epohcs"] = 3
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(bad))
    proc = subprocess.run([sys.executable, "-m", "drfkit", "reproduce", "--profile", str(path)],
                          cwd=REPO_ROOT, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2
    assert "'pendulum.epohcs'" in proc.stderr and "unknown parameter" in proc.stderr and "'epochs'" in proc.stderr
    assert "== 00_data_prep" not in proc.stdout


@pytest.mark.slow
def test_yaml_with_wrong_type_names_notebook_and_key(tmp_path):
    path = write_profile(tmp_path / "bad.yaml", load_profile("quick") | {"pend_epochs": "many"})
    proc = subprocess.run([sys.executable, "-m", "drfkit", "reproduce", "--profile", str(path)],
                          cwd=REPO_ROOT, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2
    assert "pend_epochs" in proc.stderr and "notebook 01_pendulum_training" in proc.stderr


def test_profiles_are_nested_by_section_and_flat_in_notebooks(tmp_path):
    raw = yaml.safe_load((PARAMS_DIR / "paper.yaml").read_text())
    flat = load_profile("paper")
    assert raw["pendulum"]["book"]["epochs"] == flat["pend_book_epochs"]
    assert raw["dynamics"]["regime"]["train_noise"] == flat["regime_train_noise"]
    assert raw["pedestrians"]["nuscenes_root"] == flat["nuscenes_root"]  # a name of its own
    assert raw["monoloco"]["lr"] == flat["monoloco_lr"] and raw["evaluation"]["studies"] == flat["eval_studies"]
    assert set(PATHS) == set(SPECS) and len({PATHS[k] for k in SPECS}) == len(SPECS)
    assert nest_profile(flat) == {k: v for k, v in raw.items()}  # the inverse, section for section
    assert load_profile(write_profile(tmp_path / "again.yaml", flat)) == flat


@pytest.mark.parametrize("profile, fragment", [
    ({"pend_epochs": 3}, "'pend_epochs' is written as pendulum.epochs"),   # a flat name at the top
    ({"pendulum": 3}, "'pendulum' must be a section"),
    ({"pendulum": {"book": {"epoch": 3}}}, "pendulum.book.epoch"),
])
def test_misplaced_keys_name_where_they_belong(tmp_path, profile, fragment):
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(profile))
    with pytest.raises(ParameterError, match=fragment.replace(".", r"\.")):
        load_profile(path)


def test_overrides_take_the_profile_path_or_the_notebook_name():
    assert parse_overrides(["pendulum.book.epochs=3", "pend_lr=0.01"]) == {"pend_book_epochs": 3, "pend_lr": 0.01}
    with pytest.raises(ParameterError, match="unknown parameter 'pendulum.epohcs'") as err:
        parse_overrides(["pendulum.epohcs=3"])
    assert "did you mean pendulum.epochs" in str(err.value) and "notebook name (pend_epochs)" in str(err.value)


def test_a_profile_missing_a_key_names_its_profile_path():
    values = load_profile("quick")
    del values["pend_book_epochs"]
    with pytest.raises(ParameterError, match=r"'pend_book_epochs' \[pendulum\.book\.epochs\]"):
        notebook_params("01_pendulum_training", values)


def test_schema_types_are_python_types():
    assert SPECS["pend_epochs"].type is int and SPECS["pend_eval_max_noise"].kind == "list[float]"
    assert SPECS["sim_detector"].kind == "dict"
    with pytest.raises(ParameterError, match=r"must be a list \(list\[float\]\)"):
        validate("01_pendulum_training", quick_subset("01_pendulum_training") | {"pend_eval_max_noise": 0.5})


def test_missing_profile_lists_known_ones():
    with pytest.raises(ParameterError, match=r"known profiles: \['paper', 'quick'\]"):
        load_profile("no_such_profile")
    with pytest.raises(ParameterError, match="holds the training recipes .*, not a profile"):
        load_profile("protocols")


@pytest.mark.slow
def test_notebook_stops_in_its_first_cell_on_an_unknown_parameter(tmp_path):
    """The real thing: papermill injects an unknown key; the validation cell raises."""
    import papermill as pm

    out = tmp_path / "out.ipynb"
    with pytest.raises(pm.PapermillExecutionError) as err:
        pm.execute_notebook(str(NOTEBOOKS_DIR / "05_timing.ipynb"), str(out),
                            parameters={"n_sample": 25, "profile": "test-params"},
                            progress_bar=False, kernel_name="python3", cwd=str(NOTEBOOKS_DIR))
    assert "n_sample" in str(err.value) and "05_timing" in str(err.value)
    nb = json.loads(out.read_text())
    executed = [c for c in nb["cells"] if c["cell_type"] == "code" and c.get("execution_count")]
    # parameters, injected parameters, validation: nothing after the validation cell ran
    assert len(executed) <= 3


def test_nuscenes_source_names_the_missing_key_before_any_data_is_built(tmp_path):
    from drfkit.study.params import ParameterError, load_profile, notebook_params, validate

    values = load_profile("quick") | {"ped_source": "nuscenes", "nuscenes_root": str(tmp_path), "pifpaf_predictions": ""}
    with pytest.raises(ParameterError, match="needs 'pifpaf_predictions' \\[pedestrians\\.pifpaf_predictions\\] in the profile"):
        validate("03_nuscenes_training", notebook_params("03_nuscenes_training", values))
    values["pifpaf_predictions"] = str(tmp_path / "absent")
    with pytest.raises(ParameterError, match=r"'pifpaf_predictions' \[pedestrians\.pifpaf_predictions\] = .*absent' is not a folder"):
        validate("03_nuscenes_training", notebook_params("03_nuscenes_training", values))
    values["pifpaf_predictions"] = str(tmp_path)
    assert validate("03_nuscenes_training", notebook_params("03_nuscenes_training", values)).pedestrians.source == "nuscenes"


def test_keep_outputs_copies_outputs_only_of_unchanged_code_cells(tmp_path):
    import nbformat

    sys.path.insert(0, str(REPO_ROOT / "tools"))
    import build_notebooks

    text = "# %% [markdown]\n# Why\n\n# %%\nx = 1\nx\n\n# %%\ny = 2\n"
    old = build_notebooks.parse(text, "00_data_prep")
    old.cells[1].outputs = [nbformat.v4.new_output("execute_result", {"text/plain": "1"}, execution_count=1)]
    target = tmp_path / "nb.ipynb"
    nbformat.write(old, target)
    edited = build_notebooks.parse(text.replace("# Why", "# Why, said better"), "00_data_prep")
    assert build_notebooks.keep_outputs(edited, target) == 0
    assert edited.cells[1].outputs[0]["data"]["text/plain"] == "1"
    changed = build_notebooks.parse(text.replace("x = 1", "x = 3"), "00_data_prep")
    assert build_notebooks.keep_outputs(changed, target) == 1 and changed.cells[1].outputs == []


def test_sync_markdown_gives_an_executed_notebook_the_sources_prose_and_refuses_a_code_change(tmp_path):
    import nbformat
    import pytest

    sys.path.insert(0, str(REPO_ROOT / "tools"))
    import build_notebooks

    text = "# %% [markdown]\n# Why\n\n# %%\nx = 1\nx\n"
    executed = build_notebooks.parse(text, "00_data_prep")
    executed.cells.insert(0, nbformat.v4.new_code_cell("x = 0", metadata={"tags": ["injected-parameters"]}))
    executed.cells[2].outputs = [nbformat.v4.new_output("execute_result", {"text/plain": "1"}, execution_count=1)]
    target = tmp_path / "nb.ipynb"
    nbformat.write(executed, target)
    assert build_notebooks.sync_markdown(build_notebooks.parse(text.replace("# Why", "# Why, said better"),
                                                               "00_data_prep"), target) == 1
    synced = nbformat.read(target, as_version=4)
    assert synced.cells[1].source == "Why, said better" and synced.cells[2].outputs[0]["data"]["text/plain"] == "1"
    assert synced.cells[0].source == "x = 0"
    with pytest.raises(ValueError, match="rerun the notebook"):
        build_notebooks.sync_markdown(build_notebooks.parse(text.replace("x = 1", "x = 3"), "00_data_prep"), target)


def test_keep_outputs_lets_the_parameters_cell_change_only_its_comments(tmp_path):
    import nbformat

    sys.path.insert(0, str(REPO_ROOT / "tools"))
    import build_notebooks

    def notebook(params_source):
        nb = build_notebooks.parse("# %%\nx = 1\nx\n", "00_data_prep")
        cell = nbformat.v4.new_code_cell(params_source, metadata={"tags": ["parameters"]})
        nb.cells.insert(0, cell)
        return nb

    old = notebook("# a: old words\na = 1\n")
    old.cells[1].outputs = [nbformat.v4.new_output("execute_result", {"text/plain": "1"}, execution_count=1)]
    target = tmp_path / "nb.ipynb"
    nbformat.write(old, target)
    assert build_notebooks.keep_outputs(notebook("# a [section.a]: new words\na = 1\n"), target) == 0
    assert build_notebooks.keep_outputs(notebook("# a: old words\na = 2\n"), target) == 1  # a value: re-execute
    # equal in Python, different parameter values: 1.0 or True where 1 was re-executes too
    assert build_notebooks.keep_outputs(notebook("# a: old words\na = 1.0\n"), target) == 1
    assert build_notebooks.keep_outputs(notebook("# a: old words\na = True\n"), target) == 1
