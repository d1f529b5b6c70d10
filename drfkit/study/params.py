"""Notebook parameters: one schema, validated in each notebook's first cell.

papermill only *warns* about a parameter the notebook does not declare, and happily
injects a string where an int was meant. So every notebook calls
``start_notebook(NAME, globals())`` right after its ``parameters`` cell: an unknown
key, a wrong type or an out-of-range value stops the notebook there, with a message
that names the key, the notebook and the allowed values.

The YAML profiles in ``params/`` are nested by section (``pendulum:``, ``pendulum.book:``,
``pedestrians:``, ``monoloco:``, ...; ``SCHEMA`` below is their layout, with a Python type, the
allowed values and a check for every key). Notebooks see one flat name per parameter, because
papermill injects top-level variables: a section's prefix plus the key (``pendulum.book.epochs``
is ``pend_book_epochs``), shared by every notebook that declares it (data parameters are read by
several notebooks, and must agree so that cached artefacts are found).
"""
from __future__ import annotations

import difflib
import math
import types
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, get_args, get_origin

import yaml

from drfkit.util.paths import PARAMS_DIR
from drfkit.methods.protocols import ABLATION_BUDGETS, PEDESTRIAN_PROTOCOLS, PROTOCOLS, VARIANTS
from drfkit.study.registry import STUDIES


class ParameterError(ValueError):
    """A parameter is unknown, of the wrong type or out of range."""


@dataclass(frozen=True)
class Spec:
    """One parameter: its Python type, the allowed values in words and as a check."""
    type: Any  # int, float, str, bool, dict, list[int], list[float] or list[str]
    allowed: str  # human-readable description of the allowed values
    check: Callable[[Any], bool] = lambda v: True
    doc: str = ""
    name: str = ""  # the notebook's name for it when it is not the section's prefix + key

    @property
    def kind(self) -> str:
        """``int``, ``list[float]``, ...: how messages name the type."""
        return self.type.__name__ if isinstance(self.type, type) and get_origin(self.type) is None else str(self.type)


@dataclass(frozen=True)
class Section:
    """A YAML section: its keys' notebook names are ``prefix`` + key (prefixes of nested sections add up)."""
    prefix: str
    keys: dict[str, "Spec | Section"]
    doc: str = ""


def _in01(v: float) -> bool:
    return 0.0 <= v <= 1.0


def _levels(v: list[float]) -> bool:
    return len(v) > 0 and all(map(_in01, v))


def _seeds(v: list[int]) -> bool:
    return len(v) > 0 and len(set(v)) == len(v) and min(v) >= 0


def _subset(options) -> Callable[[list[str]], bool]:
    return lambda v: len(v) > 0 and set(v) <= set(options)


PEND_MODELS = STUDIES["pendulum"].kinds
PED_MODELS = STUDIES["pedestrians"].kinds
STUDY_NAMES = tuple(STUDIES)


def _kinds_of(study: str) -> Callable[[list[str]], bool]:
    """The check of a study's ``models``: its registry entry's kinds when the check runs (a kind
    registered later, e.g. by a test, is accepted)."""
    return lambda v: _subset(STUDIES[study].kinds)(v)
_POSITIVE = ("an integer >= 1", lambda v: v >= 1)
_RATE = ("a number in (0, 1)", lambda v: 0 < v < 1)
_LEVELS = "a non-empty list of numbers in [0, 1]"
_SEEDS = "a non-empty list of distinct integers >= 0"

# The profile's layout: what params/*.yaml hold, section by section. Notebooks (papermill injects
# top-level names) see the flat names: pendulum.book.epochs is pend_book_epochs.
SCHEMA = Section("", {
    "profile": Spec(str, "a folder name of letters, digits, '_' or '-'",
                    lambda v: v.replace("_", "").replace("-", "").isalnum(), "results land in results/<profile>/"),
    "seeds": Spec(list[int], _SEEDS, _seeds, "one training run per seed; spread over seeds gives the error bars"),
    "device": Spec(str, "'auto', 'cpu' or 'cuda'", lambda v: v in ("auto", "cpu", "cuda")),
    "threads": Spec(int, "an integer >= 0 (0 keeps torch's default)", lambda v: v >= 0),
    "pendulum": Section("pend_", {
        "train_sequences": Spec(int, *_POSITIVE),
        "val_sequences": Spec(int, *_POSITIVE),
        "test_sequences": Spec(int, *_POSITIVE),
        "seq_len": Spec(int, "an integer >= 6 (the first 5 frames are clean)", lambda v: v >= 6),
        "train_max_noise": Spec(float, "a number in [0, 1]", _in01),
        "eval_max_noise": Spec(list[float], _LEVELS, _levels),
        "sweep_max_noise": Spec(list[float], _LEVELS, _levels),
        "data_seed": Spec(int, "an integer >= 0", lambda v: v >= 0),
        "models": Spec(list[str], f"a non-empty subset of {list(PEND_MODELS)}", _kinds_of("pendulum")),
        "epochs": Spec(int, *_POSITIVE),
        "batch_size": Spec(int, *_POSITIVE),
        "lr": Spec(float, *_RATE),
        "patience": Spec(int, "an integer >= 0 (0 = train every epoch)", lambda v: v >= 0,
                         "stop a run after this many epochs without a better validation NLL"),
        "protocols": Spec(list[str], f"a non-empty subset of {list(PROTOCOLS)} that holds 'paper', without repeats",
                          lambda v: "paper" in v and set(v) <= set(PROTOCOLS) and len(set(v)) == len(v),
                          "the training protocols notebook 01 trains and evaluates (drfkit.methods.protocols)"),
        "book": Section("book_", {
            "epochs": Spec(int, *_POSITIVE, "epochs of the book's protocol"),
            "batch_size": Spec(int, *_POSITIVE),
            "lr": Spec(float, *_RATE),
            "patience": Spec(int, "an integer >= 0 (0 = train every epoch)", lambda v: v >= 0,
                             "stop a book-protocol run after this many epochs without a better validation NLL"),
        }, "the book's training protocol (drfkit.methods.protocols)"),
    }, "the noisy pendulum: data, then training under the paper's protocol"),
    "dynamics": Section("", {
        "bound_particles": Spec(int, "an integer >= 10", lambda v: v >= 10,
                                "particles of the true-physics bound (drfkit.methods.oracle)"),
        "ablation": Section("ablation_", {
            "budget": Spec(str, f"one of {list(ABLATION_BUDGETS)}", lambda v: v in ABLATION_BUDGETS),
            "variants": Spec(list[str], f"a non-empty subset of {list(VARIANTS)}", _subset(VARIANTS)),
            "seeds": Spec(list[int], _SEEDS, _seeds),
            "round2": Section("round2_", {
                "budget": Spec(str, f"one of {list(ABLATION_BUDGETS)}", lambda v: v in ABLATION_BUDGETS,
                               "budget of the second round: how the models are fit (drfkit.methods.protocols.ROUND2_VARIANTS)"),
                "variants": Spec(list[str], f"a non-empty subset of {list(VARIANTS)}", _subset(VARIANTS)),
                "seeds": Spec(list[int], _SEEDS, _seeds),
            }),
        }),
        "regime": Section("regime_", {
            "train_noise": Spec(list[float], "a non-empty list of distinct numbers in [0, 1] that holds 0.5",
                                lambda v: 0.5 in v and all(map(_in01, v)) and len(set(v)) == len(v),
                                "max noise levels the noise-regime map trains at (drfkit.study.regime; 0.5 is the "
                                "book's own protocol, others are drfkit.methods.protocols.regime_variant)"),
            "seeds": Spec(list[int], _SEEDS, _seeds),
            "test_sequences": Spec(int, *_POSITIVE, "sequences of the regime map's own test split (every level)"),
        }),
    }, "notebook 01's dynamics study"),
    "pedestrians": Section("ped_", {
        "source": Spec(str, "'simulated' or 'nuscenes'", lambda v: v in ("simulated", "nuscenes")),
        "nuscenes_root": Spec(str, "'' (none) or a folder holding <nuscenes_version>/sample.json ...",
                              name="nuscenes_root"),
        "nuscenes_version": Spec(str, "e.g. 'v1.0-mini' or 'v1.0-trainval'", lambda v: len(v) > 0,
                                 name="nuscenes_version"),
        "pifpaf_predictions": Spec(str, "'' (none) or a folder with one sub-folder of PifPaf JSON per noise level",
                                   name="pifpaf_predictions"),
        "n_scenes": Spec(int, "an integer >= 3 (train/val/test split by scene)", lambda v: v >= 3),
        "frames_per_scene": Spec(int, "an integer >= 2", lambda v: v >= 2),
        "train_p": Spec(float, "a number in [0, 1]", _in01),
        "eval_p": Spec(list[float], _LEVELS, _levels),
        "sweep_p": Spec(list[float], _LEVELS, _levels),
        "seq_len": Spec(int, *_POSITIVE),
        "data_seed": Spec(int, "an integer >= 0", lambda v: v >= 0),
        "sim_detector": Spec(dict, "a mapping of DetectorConfig fields (see drfkit.data.sim_detector)",
                             name="sim_detector"),
        "models": Spec(list[str], f"a non-empty subset of {list(PED_MODELS)}", _kinds_of("pedestrians")),
        "epochs": Spec(int, *_POSITIVE),
        "batch_size": Spec(int, *_POSITIVE),
        "lr": Spec(float, *_RATE),
        "protocols": Spec(list[str], f"a non-empty subset of {list(PEDESTRIAN_PROTOCOLS)} that holds 'paper', "
                                     "without repeats",
                          lambda v: "paper" in v and set(v) <= set(PEDESTRIAN_PROTOCOLS) and len(set(v)) == len(v),
                          "the training protocols notebook 02 trains and notebooks 03 and 05 judge "
                          "(drfkit.methods.protocols.PEDESTRIAN_PROTOCOLS; Monoloco's runs are shared)"),
    }, "pedestrian depth: data (simulated or nuScenes + PifPaf), then the DRF family's training"),
    "monoloco": Section("monoloco_", {
        "epochs": Spec(int, *_POSITIVE),
        "batch_size": Spec(int, *_POSITIVE),
        "lr": Spec(float, *_RATE),
    }, "Monoloco's own schedule"),
    "evaluation": Section("eval_", {
        "studies": Spec(list[str], f"a non-empty subset of {list(STUDY_NAMES)}, without repeats",
                        lambda v: len(v) > 0 and set(v) <= set(STUDY_NAMES) and len(set(v)) == len(v),
                        "which studies notebooks 03 and 05 evaluate (both, unless one's models are not trained "
                        "yet: its claims are then listed as not evaluated)"),
    }),
    "uncertainty": Section("", {
        "n_samples": Spec(int, "an integer >= 1 (Monte Carlo dropout passes)", lambda v: v >= 1),
        "dropout_rates": Spec(list[float], "a non-empty list of numbers in [0, 1)",
                              lambda v: len(v) > 0 and all(0 <= x < 1 for x in v)),
        "interval_level": Spec(float, "a number in (0, 1), e.g. 0.95", lambda v: 0 < v < 1),
    }),
    "timing": Section("timing_", {
        "batch_sizes": Spec(list[int], "a non-empty list of integers >= 1", lambda v: len(v) > 0 and min(v) >= 1),
        "threads": Spec(list[int], "a non-empty list of integers >= 1", lambda v: len(v) > 0 and min(v) >= 1),
        "min_run_time": Spec(float, "seconds > 0 per measurement", lambda v: v > 0),
    }),
    "gating": Section("gating_", {
        "picp_tolerance": Spec(float, "a number in [0, 1] (fraction, e.g. 0.01 = 1 point)", _in01),
        "sweep_points": Spec(int, "an integer >= 2", lambda v: v >= 2),
        "timing_frames": Spec(int, "an integer >= 0 (0 = every test frame)", lambda v: v >= 0,
                              "about this many real frames, of evenly spaced test sequences, are what the gating "
                              "times are measured on; metrics use every test sequence"),
    }),
})


def _flatten_schema(section: Section, prefix: str = "", path: tuple[str, ...] = ()):
    for key, item in section.keys.items():
        if isinstance(item, Section):
            yield from _flatten_schema(item, prefix + item.prefix, path + (key,))
        else:
            yield (item.name or prefix + key), path + (key,), item


# the flat (notebook) name of every parameter -> its spec, and -> its path in the YAML profile
SPECS: dict[str, Spec] = {name: spec for name, _, spec in _flatten_schema(SCHEMA)}
PATHS: dict[str, tuple[str, ...]] = {name: path for name, path, _ in _flatten_schema(SCHEMA)}
_BY_PATH = {".".join(path): name for name, path in PATHS.items()}
assert len(SPECS) == len(_BY_PATH), "two parameters share a notebook name"


_COMMON = ["profile", "seeds", "device", "threads"]
_PEND_DATA = ["pend_train_sequences", "pend_val_sequences", "pend_test_sequences", "pend_seq_len",
              "pend_train_max_noise", "pend_eval_max_noise", "pend_sweep_max_noise", "pend_data_seed"]
_PEND_TRAIN = ["pend_models", "pend_epochs", "pend_batch_size", "pend_lr", "pend_patience", "pend_protocols",
               "pend_book_epochs", "pend_book_batch_size", "pend_book_lr", "pend_book_patience"]
_DYNAMICS = ["bound_particles", "ablation_budget", "ablation_variants", "ablation_seeds", "ablation_round2_budget",
             "ablation_round2_variants", "ablation_round2_seeds", "regime_train_noise",
             "regime_seeds", "regime_test_sequences"]
_PED_DATA = ["ped_source", "nuscenes_root", "nuscenes_version", "pifpaf_predictions", "ped_n_scenes",
             "ped_frames_per_scene", "ped_train_p", "ped_eval_p", "ped_sweep_p", "ped_seq_len",
             "ped_data_seed", "sim_detector"]
_PED_TRAIN = ["ped_models", "ped_epochs", "ped_batch_size", "ped_lr", "ped_protocols", "monoloco_epochs",
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
    "04_timing": _COMMON + ["n_samples"] + _TIMING + _PEND_DATA + _PEND_TRAIN,
    "05_competency_gating": _COMMON + _EVAL + _PEND_DATA + _PEND_TRAIN + _PED_DATA + _PED_TRAIN + _UNC + _GATING,
}


# what a command line reads when it needs less than a notebook's whole set: the inference benchmark
# (``python -m drfkit bench``) reads notebook 04's timing keys, not the pendulum's that its training-speed
# part needs
COMMANDS: dict[str, list[str]] = {"bench": _COMMON + ["n_samples"] + _TIMING}


def _key_set(name: str) -> list[str]:
    """The parameters of a notebook (``NOTEBOOKS``) or a command (``COMMANDS``)."""
    if name in NOTEBOOKS:
        return NOTEBOOKS[name]
    if name in COMMANDS:
        return COMMANDS[name]
    raise ParameterError(f"unknown notebook {name!r}; known: {sorted(NOTEBOOKS)} (and commands {sorted(COMMANDS)})")


class Params(types.SimpleNamespace):
    """Validated parameters of one notebook; attribute access, plus ``as_dict()``."""

    def as_dict(self) -> dict[str, Any]:
        return dict(vars(self))


def _named(key: str) -> str:
    """'pend_book_epochs' [pendulum.book.epochs]: a notebook name with where it sits in a profile."""
    return f"'{key}' [{'.'.join(PATHS[key])}]" if key in PATHS else f"'{key}'"


def _coerce(key: str, typ: Any, value: Any, where: str) -> Any:
    def fail(expected: str) -> ParameterError:
        return ParameterError(
            f"{where}: parameter {_named(key)} must be {expected}, got {value!r} ({type(value).__name__}); "
            f"allowed: {SPECS[key].allowed}"
        )

    if typ is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise fail("an integer")
        return int(value)
    if typ is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise fail("a finite number")
        return float(value)
    if typ is str:
        if not isinstance(value, str):
            raise fail("a string")
        return value
    if typ is bool:
        if not isinstance(value, bool):
            raise fail("true or false")
        return value
    if typ is dict:
        if not isinstance(value, dict):
            raise fail("a mapping")
        return dict(value)
    if get_origin(typ) is list:
        if not isinstance(value, (list, tuple)):
            raise fail(f"a list ({SPECS[key].kind})")
        (inner,) = get_args(typ)
        return [_coerce(key, inner, v, where) for v in value]
    raise AssertionError(f"unknown type {typ}")


def validate(notebook: str, values: dict[str, Any]) -> Params:
    """Check ``values`` against the schema of ``notebook``; return them as ``Params``.

    Every key of ``notebook`` must be present (the parameters cell defines them all);
    any other key is an error.
    """
    allowed_keys = _key_set(notebook)
    where = f"notebook {notebook}" if notebook in NOTEBOOKS else f"python -m drfkit {notebook}"
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
        value = _coerce(key, spec.type, values[key], where)
        if not spec.check(value):
            raise ParameterError(
                f"{where}: parameter {_named(key)} = {value!r} is out of range; allowed: {spec.allowed}"
            )
        out[key] = value
    if out.get("ped_source") == "nuscenes":
        for key, holds in (("nuscenes_root", f"{out.get('nuscenes_version', '<version>')}/sample.json and the other "
                                             "tables"),
                           ("pifpaf_predictions", "one sub-folder of PifPaf JSON per noise level (p0.01, ...)")):
            if key in out and not out[key]:
                raise ParameterError(f"{where}: ped_source 'nuscenes' needs {_named(key)} in the profile: the "
                                     f"folder that holds {holds} (README, 'Real nuScenes data'); it is empty")
            if key in out and not Path(out[key]).is_dir():
                raise ParameterError(f"{where}: parameter {_named(key)} = {out[key]!r} is not a folder on this machine")
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


def _section_at(path: tuple[str, ...]) -> Section:
    section = SCHEMA
    for key in path:
        section = section.keys[key]
    return section


def flatten_profile(nested: dict[str, Any], where: str) -> dict[str, Any]:
    """A profile's nested sections -> {notebook name: value}; unknown keys and misplaced ones are errors."""
    flat: dict[str, Any] = {}

    def walk(values: Any, path: tuple[str, ...]) -> None:
        section = _section_at(path)
        label = ".".join(path) or "the top level"
        if not isinstance(values, dict):
            raise ParameterError(f"{where}: '{label}' must be a section (a mapping of key: value), got {values!r}")
        for key, value in values.items():
            item = section.keys.get(key)
            if item is None:
                hint = ""
                if key in SPECS:  # a flat name where a nested one belongs (profiles before sections)
                    hint = f"; '{key}' is written as {'.'.join(PATHS[key])} (sections in params/quick.yaml)"
                raise ParameterError(f"{where}: unknown parameter {'.'.join(path + (str(key),))!r}{hint}; "
                                     f"{label} holds: {list(section.keys)}")
            if isinstance(item, Section):
                walk(value, path + (key,))
            else:
                flat[_BY_PATH[".".join(path + (key,))]] = value

    walk(nested, ())
    return flat


def nest_profile(flat: dict[str, Any]) -> dict[str, Any]:
    """{notebook name: value} -> the profile's nested sections (``flatten_profile``'s inverse)."""
    unknown = sorted(set(flat) - set(SPECS))
    if unknown:
        raise ParameterError(f"unknown parameter(s) {unknown}; known parameters: {sorted(SPECS)}")
    nested: dict[str, Any] = {}
    for name, value in flat.items():
        *sections, key = PATHS[name]
        node = nested
        for s in sections:
            node = node.setdefault(s, {})
        node[key] = value
    return nested


def write_profile(path: str | Path, flat: dict[str, Any]) -> Path:
    """Write ``flat`` (e.g. ``load_profile("quick") | {...}``) as a nested YAML profile at ``path``."""
    path = Path(path)
    path.write_text(yaml.safe_dump(nest_profile(flat), sort_keys=False))
    return path


def load_profile(profile: str | Path) -> dict[str, Any]:
    """Read ``params/<profile>.yaml`` (or a path): its sections checked against ``SCHEMA``,
    returned flat, ``{notebook name: value}``."""
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
    return flatten_profile(values, str(path))


def parse_overrides(items: list[str] | None) -> dict:
    """``["key=yaml value", ...]`` -> {notebook name: value}, for the ``--set`` option of
    ``drfkit.book.pipeline`` and ``drfkit.study.studies``; a key is a profile path (``pendulum.epochs``) or
    the notebook name (``pend_epochs``)."""
    out = {}
    for item in items or []:
        key, sep, text = item.partition("=")
        if not sep or not key:
            raise ParameterError(f"--set expects KEY=VALUE (VALUE in YAML, e.g. evaluation.studies=[pedestrians]), "
                                 f"got {item!r}")
        name = _BY_PATH.get(key, key)
        if name not in SPECS:
            close = difflib.get_close_matches(key, list(_BY_PATH) + list(SPECS), n=3)
            hint = f" (did you mean {' or '.join(close)}?)" if close else ""
            raise ParameterError(f"--set: unknown parameter {key!r}{hint}; a key is a profile path "
                                 f"(pendulum.epochs) or its notebook name (pend_epochs); known paths: "
                                 f"{sorted(_BY_PATH)}")
        try:
            out[name] = yaml.safe_load(text)
        except yaml.YAMLError as exc:
            raise ParameterError(f"--set {key}: {text!r} is not a YAML value ({exc})") from None
    return out


def notebook_params(notebook: str, profile_values: dict[str, Any]) -> dict[str, Any]:
    """The subset of a profile that ``notebook`` (or a command of ``COMMANDS``) declares, validated (raises on error)."""
    keys = _key_set(notebook)
    subset = {k: profile_values[k] for k in keys if k in profile_values}
    missing = [k for k in keys if k not in subset]
    if missing:
        user = f"notebook {notebook}" if notebook in NOTEBOOKS else f"python -m drfkit {notebook}"
        raise ParameterError(f"profile lacks parameter(s) {', '.join(_named(k) for k in missing)} needed by {user}")
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
