"""Notebook parameters: one schema, validated in each notebook's first cell.

papermill only *warns* about a parameter the notebook does not declare, and happily
injects a string where an int was meant. So every notebook calls
``start_notebook(NAME, globals())`` right after its ``parameters`` cell: an unknown
key, a wrong type or an out-of-range value stops the notebook there, with a message
that names the key, the notebook and the allowed values.

The YAML profiles in ``params/`` are flat: one key per parameter, shared by every
notebook that declares it (data parameters are read by several notebooks, and must
agree so that cached artefacts are found).
"""
from __future__ import annotations

import math
import types
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import yaml

from drfkit.paths import PARAMS_DIR
from drfkit.protocols import ABLATION_BUDGETS, PROTOCOLS, VARIANTS
from drfkit.registry import STUDIES


class ParameterError(ValueError):
    """A parameter is unknown, of the wrong type or out of range."""


@dataclass(frozen=True)
class Spec:
    kind: str  # 'int' | 'float' | 'str' | 'bool' | 'list[int]' | 'list[float]' | 'list[str]' | 'dict'
    allowed: str  # human-readable description of the allowed values
    check: Callable[[Any], bool] = lambda v: True
    doc: str = ""


def _in01(v: float) -> bool:
    return 0.0 <= v <= 1.0


PEND_MODELS = STUDIES["pendulum"].kinds
PED_MODELS = STUDIES["pedestrians"].kinds
STUDY_NAMES = tuple(STUDIES)

SPECS: dict[str, Spec] = {
    # -- common -----------------------------------------------------------------------
    "profile": Spec("str", "a folder name of letters, digits, '_' or '-'",
                    lambda v: v.replace("_", "").replace("-", "").isalnum(),
                    "results land in results/<profile>/"),
    "seeds": Spec("list[int]", "a non-empty list of distinct integers >= 0",
                  lambda v: len(v) > 0 and len(set(v)) == len(v) and min(v) >= 0,
                  "one training run per seed; spread over seeds gives the error bars"),
    "device": Spec("str", "'auto', 'cpu' or 'cuda'", lambda v: v in ("auto", "cpu", "cuda")),
    "threads": Spec("int", "an integer >= 0 (0 keeps torch's default)", lambda v: v >= 0),
    # -- pendulum data --------------------------------------------------------------------
    "pend_train_sequences": Spec("int", "an integer >= 1", lambda v: v >= 1),
    "pend_val_sequences": Spec("int", "an integer >= 1", lambda v: v >= 1),
    "pend_test_sequences": Spec("int", "an integer >= 1", lambda v: v >= 1),
    "pend_seq_len": Spec("int", "an integer >= 6 (the first 5 frames are clean)", lambda v: v >= 6),
    "pend_train_max_noise": Spec("float", "a number in [0, 1]", _in01),
    "pend_eval_max_noise": Spec("list[float]", "a non-empty list of numbers in [0, 1]",
                                lambda v: len(v) > 0 and all(map(_in01, v))),
    "pend_sweep_max_noise": Spec("list[float]", "a non-empty list of numbers in [0, 1]",
                                 lambda v: len(v) > 0 and all(map(_in01, v))),
    "pend_data_seed": Spec("int", "an integer >= 0", lambda v: v >= 0),
    # -- pendulum training ---------------------------------------------------------------
    "pend_models": Spec("list[str]", f"a non-empty subset of {list(PEND_MODELS)}",
                        lambda v: len(v) > 0 and set(v) <= set(PEND_MODELS)),
    "pend_epochs": Spec("int", "an integer >= 1", lambda v: v >= 1),
    "pend_batch_size": Spec("int", "an integer >= 1", lambda v: v >= 1),
    "pend_lr": Spec("float", "a number in (0, 1)", lambda v: 0 < v < 1),
    "pend_patience": Spec("int", "an integer >= 0 (0 = train every epoch)", lambda v: v >= 0,
                          "stop a run after this many epochs without a better validation NLL"),
    "pend_protocols": Spec("list[str]", f"a non-empty subset of {list(PROTOCOLS)} that holds 'paper', without repeats",
                           lambda v: "paper" in v and set(v) <= set(PROTOCOLS) and len(set(v)) == len(v),
                           "the training protocols notebook 01 trains and evaluates (drfkit.protocols)"),
    "pend_book_epochs": Spec("int", "an integer >= 1", lambda v: v >= 1, "epochs of the book's protocol"),
    "pend_book_batch_size": Spec("int", "an integer >= 1", lambda v: v >= 1),
    "pend_book_lr": Spec("float", "a number in (0, 1)", lambda v: 0 < v < 1),
    "pend_book_patience": Spec("int", "an integer >= 0 (0 = train every epoch)", lambda v: v >= 0,
                               "stop a book-protocol run after this many epochs without a better validation NLL"),
    # -- the dynamics study (notebook 01) ------------------------------------------------------
    "bound_particles": Spec("int", "an integer >= 10", lambda v: v >= 10,
                            "particles of the true-physics bound (drfkit.oracle)"),
    "ablation_budget": Spec("str", f"one of {list(ABLATION_BUDGETS)}", lambda v: v in ABLATION_BUDGETS),
    "ablation_variants": Spec("list[str]", f"a non-empty subset of {list(VARIANTS)}",
                              lambda v: len(v) > 0 and set(v) <= set(VARIANTS)),
    "ablation_seeds": Spec("list[int]", "a non-empty list of distinct integers >= 0",
                           lambda v: len(v) > 0 and len(set(v)) == len(v) and min(v) >= 0),
    "regime_train_noise": Spec("list[float]", "a non-empty list of distinct numbers in [0, 1] that holds 0.5",
                               lambda v: 0.5 in v and all(map(_in01, v)) and len(set(v)) == len(v),
                               "max noise levels the noise-regime map trains at (drfkit.regime; 0.5 is the "
                               "book's own protocol, others are drfkit.protocols.regime_variant)"),
    "regime_seeds": Spec("list[int]", "a non-empty list of distinct integers >= 0",
                         lambda v: len(v) > 0 and len(set(v)) == len(v) and min(v) >= 0),
    "regime_test_sequences": Spec("int", "an integer >= 1", lambda v: v >= 1,
                                  "sequences of the regime map's own test split (at every sweep level)"),
    # -- pedestrian data ---------------------------------------------------------------------
    "ped_source": Spec("str", "'simulated' or 'nuscenes'", lambda v: v in ("simulated", "nuscenes")),
    "nuscenes_root": Spec("str", "'' (none) or a folder holding <nuscenes_version>/sample.json ..."),
    "nuscenes_version": Spec("str", "e.g. 'v1.0-mini' or 'v1.0-trainval'", lambda v: len(v) > 0),
    "pifpaf_predictions": Spec("str", "'' (none) or a folder with one sub-folder of PifPaf JSON per noise level"),
    "ped_n_scenes": Spec("int", "an integer >= 3 (train/val/test split by scene)", lambda v: v >= 3),
    "ped_frames_per_scene": Spec("int", "an integer >= 2", lambda v: v >= 2),
    "ped_train_p": Spec("float", "a number in [0, 1]", _in01),
    "ped_eval_p": Spec("list[float]", "a non-empty list of numbers in [0, 1]",
                       lambda v: len(v) > 0 and all(map(_in01, v))),
    "ped_sweep_p": Spec("list[float]", "a non-empty list of numbers in [0, 1]",
                        lambda v: len(v) > 0 and all(map(_in01, v))),
    "ped_seq_len": Spec("int", "an integer >= 1", lambda v: v >= 1),
    "ped_data_seed": Spec("int", "an integer >= 0", lambda v: v >= 0),
    "sim_detector": Spec("dict", "a mapping of DetectorConfig fields (see drfkit.data.sim_detector)"),
    # -- pedestrian training ----------------------------------------------------------------
    "ped_models": Spec("list[str]", f"a non-empty subset of {list(PED_MODELS)}",
                       lambda v: len(v) > 0 and set(v) <= set(PED_MODELS)),
    "ped_epochs": Spec("int", "an integer >= 1", lambda v: v >= 1),
    "ped_batch_size": Spec("int", "an integer >= 1", lambda v: v >= 1),
    "ped_lr": Spec("float", "a number in (0, 1)", lambda v: 0 < v < 1),
    "monoloco_epochs": Spec("int", "an integer >= 1", lambda v: v >= 1),
    "monoloco_batch_size": Spec("int", "an integer >= 1", lambda v: v >= 1),
    "monoloco_lr": Spec("float", "a number in (0, 1)", lambda v: 0 < v < 1),
    # -- evaluation ------------------------------------------------------------------------
    "eval_studies": Spec("list[str]", f"a non-empty subset of {list(STUDY_NAMES)}, without repeats",
                         lambda v: len(v) > 0 and set(v) <= set(STUDY_NAMES) and len(set(v)) == len(v),
                         "which studies notebooks 03 and 05 evaluate (both, unless one's models are not "
                         "trained yet: its claims are then listed as not evaluated)"),
    # -- uncertainty ---------------------------------------------------------------------
    "n_samples": Spec("int", "an integer >= 1 (Monte Carlo dropout passes)", lambda v: v >= 1),
    "dropout_rates": Spec("list[float]", "a non-empty list of numbers in [0, 1)",
                          lambda v: len(v) > 0 and all(0 <= x < 1 for x in v)),
    "interval_level": Spec("float", "a number in (0, 1), e.g. 0.95", lambda v: 0 < v < 1),
    # -- timing ------------------------------------------------------------------------------
    "timing_batch_sizes": Spec("list[int]", "a non-empty list of integers >= 1",
                               lambda v: len(v) > 0 and min(v) >= 1),
    "timing_threads": Spec("list[int]", "a non-empty list of integers >= 1",
                           lambda v: len(v) > 0 and min(v) >= 1),
    "timing_min_run_time": Spec("float", "seconds > 0 per measurement", lambda v: v > 0),
    # -- gating ------------------------------------------------------------------------------
    "gating_picp_tolerance": Spec("float", "a number in [0, 1] (fraction, e.g. 0.01 = 1 point)", _in01),
    "gating_sweep_points": Spec("int", "an integer >= 2", lambda v: v >= 2),
    "gating_timing_frames": Spec("int", "an integer >= 0 (0 = every test frame)", lambda v: v >= 0,
                                 "about this many real frames, of evenly spaced test sequences, are what the "
                                 "gating times are measured on; metrics use every test sequence"),
}

_COMMON = ["profile", "seeds", "device", "threads"]
_PEND_DATA = ["pend_train_sequences", "pend_val_sequences", "pend_test_sequences", "pend_seq_len",
              "pend_train_max_noise", "pend_eval_max_noise", "pend_sweep_max_noise", "pend_data_seed"]
_PEND_TRAIN = ["pend_models", "pend_epochs", "pend_batch_size", "pend_lr", "pend_patience", "pend_protocols",
               "pend_book_epochs", "pend_book_batch_size", "pend_book_lr", "pend_book_patience"]
_DYNAMICS = ["bound_particles", "ablation_budget", "ablation_variants", "ablation_seeds", "regime_train_noise",
             "regime_seeds", "regime_test_sequences"]
_PED_DATA = ["ped_source", "nuscenes_root", "nuscenes_version", "pifpaf_predictions", "ped_n_scenes",
             "ped_frames_per_scene", "ped_train_p", "ped_eval_p", "ped_sweep_p", "ped_seq_len",
             "ped_data_seed", "sim_detector"]
_PED_TRAIN = ["ped_models", "ped_epochs", "ped_batch_size", "ped_lr", "monoloco_epochs",
              "monoloco_batch_size", "monoloco_lr"]
_UNC = ["n_samples", "dropout_rates", "interval_level"]
_TIMING = ["timing_batch_sizes", "timing_threads", "timing_min_run_time"]
_GATING = ["gating_picp_tolerance", "gating_sweep_points", "gating_timing_frames"]
_EVAL = ["eval_studies"]

NOTEBOOKS: dict[str, list[str]] = {
    "00_data_prep": _COMMON + _PEND_DATA + _PED_DATA,
    "01_pendulum_training": _COMMON + _PEND_DATA + _PEND_TRAIN + _UNC + _DYNAMICS,
    "02_nuscenes_training": _COMMON + _PED_DATA + _PED_TRAIN + _UNC,
    "03_ood_noise_evaluation": _COMMON + _EVAL + _PEND_DATA + _PEND_TRAIN + _PED_DATA + _PED_TRAIN + _UNC,
    "04_timing": _COMMON + ["n_samples"] + _TIMING,
    "05_competency_gating": _COMMON + _EVAL + _PEND_DATA + _PEND_TRAIN + _PED_DATA + _PED_TRAIN + _UNC + _GATING,
}


class Params(types.SimpleNamespace):
    """Validated parameters of one notebook; attribute access, plus ``as_dict()``."""

    def as_dict(self) -> dict[str, Any]:
        return dict(vars(self))


def _coerce(key: str, kind: str, value: Any, where: str) -> Any:
    def fail(expected: str) -> ParameterError:
        return ParameterError(
            f"{where}: parameter '{key}' must be {expected}, got {value!r} ({type(value).__name__}); "
            f"allowed: {SPECS[key].allowed}"
        )

    if kind == "int":
        if isinstance(value, bool) or not isinstance(value, int):
            raise fail("an integer")
        return int(value)
    if kind == "float":
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise fail("a finite number")
        return float(value)
    if kind == "str":
        if not isinstance(value, str):
            raise fail("a string")
        return value
    if kind == "bool":
        if not isinstance(value, bool):
            raise fail("true or false")
        return value
    if kind == "dict":
        if not isinstance(value, dict):
            raise fail("a mapping")
        return dict(value)
    if kind.startswith("list["):
        if not isinstance(value, (list, tuple)):
            raise fail(f"a list ({kind})")
        inner = kind[5:-1]
        return [_coerce(key, inner, v, where) for v in value]
    raise AssertionError(f"unknown kind {kind}")


def validate(notebook: str, values: dict[str, Any]) -> Params:
    """Check ``values`` against the schema of ``notebook``; return them as ``Params``.

    Every key of ``notebook`` must be present (the parameters cell defines them all);
    any other key is an error.
    """
    if notebook not in NOTEBOOKS:
        raise ParameterError(f"unknown notebook {notebook!r}; known: {sorted(NOTEBOOKS)}")
    allowed_keys = NOTEBOOKS[notebook]
    where = f"notebook {notebook}"
    unknown = sorted(set(values) - set(allowed_keys))
    if unknown:
        raise ParameterError(
            f"{where}: unknown parameter(s) {unknown}; this notebook accepts: {allowed_keys}"
        )
    missing = [k for k in allowed_keys if k not in values]
    if missing:
        raise ParameterError(f"{where}: parameter(s) {missing} missing; define them in the parameters cell")
    out = {}
    for key in allowed_keys:
        spec = SPECS[key]
        value = _coerce(key, spec.kind, values[key], where)
        if not spec.check(value):
            raise ParameterError(
                f"{where}: parameter '{key}' = {value!r} is out of range; allowed: {spec.allowed}"
            )
        out[key] = value
    if out.get("ped_source") == "nuscenes":
        for key, holds in (("nuscenes_root", f"{out.get('nuscenes_version', '<version>')}/sample.json and the other "
                                             "tables"),
                           ("pifpaf_predictions", "one sub-folder of PifPaf JSON per noise level (p0.01, ...)")):
            if key in out and not out[key]:
                raise ParameterError(f"{where}: ped_source 'nuscenes' needs '{key}' in the profile: the folder that "
                                     f"holds {holds} (README, 'Real nuScenes data'); it is empty")
            if key in out and not Path(out[key]).is_dir():
                raise ParameterError(f"{where}: parameter '{key}' = {out[key]!r} is not a folder on this machine")
    if "sim_detector" in out:
        from drfkit.data.sim_detector import DetectorConfig

        try:
            DetectorConfig.from_dict(out["sim_detector"])
        except (ValueError, TypeError) as exc:
            raise ParameterError(f"{where}: parameter 'sim_detector': {exc}") from exc
    return Params(**out)


_IPYTHON_NAMES = {"In", "Out", "get_ipython", "exit", "quit", "open"}


def notebook_globals(namespace: dict[str, Any]) -> dict[str, Any]:
    """The parameters defined in a notebook namespace: every public name that is not a
    module, function, class or IPython builtin (the first cells define nothing else)."""
    return {
        k: v
        for k, v in namespace.items()
        if not k.startswith("_")
        and k not in _IPYTHON_NAMES
        and not isinstance(v, (types.ModuleType, types.FunctionType, types.BuiltinFunctionType, type))
    }


def load_profile(profile: str | Path) -> dict[str, Any]:
    """Read ``params/<profile>.yaml`` (or a path) and check every key exists in the schema."""
    path = Path(profile)
    if path.suffix not in (".yaml", ".yml"):
        path = PARAMS_DIR / f"{profile}.yaml"
    if not path.is_file():
        known = sorted(p.stem for p in PARAMS_DIR.glob("*.yaml"))
        raise ParameterError(f"parameter file {path} does not exist; known profiles: {known}")
    with open(path) as fh:
        values = yaml.safe_load(fh) or {}
    if not isinstance(values, dict):
        raise ParameterError(f"{path}: expected a mapping of parameter: value")
    unknown = sorted(set(values) - set(SPECS))
    if unknown:
        raise ParameterError(
            f"{path}: unknown parameter(s) {unknown}; known parameters: {sorted(SPECS)}"
        )
    return values


def parse_overrides(items: list[str] | None) -> dict:
    """``["key=yaml value", ...]`` -> {key: value}, keys checked against the schema (the
    ``--set`` option of ``drfkit.pipeline`` and ``drfkit.studies``)."""
    out = {}
    for item in items or []:
        key, sep, text = item.partition("=")
        if not sep or not key:
            raise ParameterError(f"--set expects KEY=VALUE (VALUE in YAML, e.g. eval_studies=[pedestrians]), "
                                 f"got {item!r}")
        if key not in SPECS:
            raise ParameterError(f"--set: unknown parameter {key!r}; known parameters: {sorted(SPECS)}")
        try:
            out[key] = yaml.safe_load(text)
        except yaml.YAMLError as exc:
            raise ParameterError(f"--set {key}: {text!r} is not a YAML value ({exc})") from None
    return out


def notebook_params(notebook: str, profile_values: dict[str, Any]) -> dict[str, Any]:
    """The subset of a profile that ``notebook`` declares, validated (raises on error)."""
    subset = {k: profile_values[k] for k in NOTEBOOKS[notebook] if k in profile_values}
    missing = [k for k in NOTEBOOKS[notebook] if k not in subset]
    if missing:
        raise ParameterError(f"profile lacks parameter(s) {missing} needed by notebook {notebook}")
    validate(notebook, subset)
    return subset


def for_notebook(notebook: str, values: dict[str, Any]) -> Params:
    """The validated parameters of ``notebook`` from a whole profile's values (``load_profile``,
    overrides merged): what the command-line tools use to run as that notebook would."""
    return validate(notebook, notebook_params(notebook, values))


def for_command(notebook: str, profile: str) -> Params | None:
    """``for_notebook`` of a named profile for a command line: None after printing the
    parameter error (the command then exits with status 2)."""
    try:
        return for_notebook(notebook, load_profile(profile))
    except ParameterError as exc:
        print(f"parameter error: {exc}")
        return None
