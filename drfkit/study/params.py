"""Notebook parameters: validated in each notebook's first cell, handed over as the typed profile.

papermill only *warns* about a parameter the notebook does not declare, and happily
injects a string where an int was meant. So every notebook calls
``start_notebook(NAME, globals())`` right after its ``parameters`` cell: an unknown
key, a wrong type or an out-of-range value stops the notebook there, with a message
that names the key, the notebook and the allowed values.

The YAML profiles in ``params/`` are nested by section (``drfkit.study.schema.SCHEMA``: a Python
type, the allowed values and a check for every key). Notebooks see one flat name per parameter,
because papermill injects top-level variables: a section's prefix plus the key
(``pendulum.book.epochs`` is ``pend_book_epochs``), shared by every notebook that declares it (data
parameters are read by several notebooks, and must agree so that cached artefacts are found). That
flat form lives only at the papermill boundary: ``validate`` returns the typed, nested profile
(``drfkit.study.profile.Profile``, ``P.pendulum.book.epochs``) that the study and book layers read.
"""
from __future__ import annotations

import difflib
import math
import types
from pathlib import Path
from typing import Any, get_args, get_origin

import yaml

from drfkit.study.profile import Profile, build_profile
from drfkit.study.registry import STUDIES
from drfkit.study.schema import _BY_PATH, PATHS, SCHEMA, SPECS, ParameterError, Section
from drfkit.util.paths import PARAMS_DIR

_COMMON = ["profile", "seeds", "device", "threads"]
_PEND_DATA = ["pend_train_sequences", "pend_val_sequences", "pend_test_sequences", "pend_seq_len",
              "pend_train_max_noise", "pend_eval_max_noise", "pend_sweep_max_noise", "pend_data_seed",
              "pend_test_seed"]
_PEND_TRAIN = ["pend_models", "pend_epochs", "pend_batch_size", "pend_lr", "pend_patience", "pend_protocols",
               "pend_book_models", "pend_book_epochs", "pend_book_batch_size", "pend_book_lr", "pend_book_patience",
               "pend_book_restarts"]
_DYNAMICS = ["reference_particles", "ablation_budget", "ablation_variants", "ablation_seeds",
             "ablation_round2_budget", "ablation_round2_variants", "ablation_round2_seeds", "regime_train_noise",
             "regime_seeds", "regime_test_sequences", "ablation_round3_budget", "ablation_round3_variants",
             "ablation_round3_seeds",
             "limit_sequences", "limit_particles"]
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
    "01_pendulum_training": _COMMON + _PEND_DATA + _PEND_TRAIN + _UNC,
    "02_pendulum_dynamics": _COMMON + _PEND_DATA + _PEND_TRAIN + _UNC + _DYNAMICS,
    "03_nuscenes_training": _COMMON + _PED_DATA + _PED_TRAIN + _UNC,
    "04_ood_noise_evaluation": _COMMON + _EVAL + _PEND_DATA + _PEND_TRAIN + _PED_DATA + _PED_TRAIN + _UNC
                               + ["limit_sequences", "limit_particles", "pend_sweep_sequences"],
    "05_timing": _COMMON + ["n_samples"] + _TIMING + ["timing_paired_rounds"] + _PEND_DATA + _PEND_TRAIN,
    "06_competency_gating": _COMMON + _EVAL + _PEND_DATA + _PEND_TRAIN + _PED_DATA + _PED_TRAIN + _UNC + _GATING,
}


# what a command line reads when it needs less than a notebook's whole set: the inference benchmark
# (``python -m drfkit bench``) reads notebook 05's timing keys, not the pendulum's that its training-speed
# part needs
COMMANDS: dict[str, list[str]] = {"bench": _COMMON + ["n_samples"] + _TIMING, "simstats": _COMMON + _PED_DATA}


def _key_set(name: str) -> list[str]:
    """The parameters of a notebook (``NOTEBOOKS``) or a command (``COMMANDS``)."""
    if name in NOTEBOOKS:
        return NOTEBOOKS[name]
    if name in COMMANDS:
        return COMMANDS[name]
    raise ParameterError(f"unknown notebook {name!r}; known: {sorted(NOTEBOOKS)} (and commands {sorted(COMMANDS)})")


def _named(key: str) -> str:
    """'pend_book_epochs' [pendulum.book.epochs]: a notebook name with where it sits in a profile."""
    return f"'{key}' [{'.'.join(PATHS[key])}]" if key in PATHS else f"'{key}'"


def _coerce(key: str, typ: Any, value: Any, where: str) -> Any:
    def fail(expected: str) -> ParameterError:
        return ParameterError(
            f"{where}: parameter {_named(key)} must be {expected}, got {value!r} ({type(value).__name__}); "
            f"allowed: {allowed_text(key)}"
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


# Spec.registry -> the field of a study's entry that bounds the list
_REGISTRY_FIELDS = {"kinds": "kinds", "protocols": "all_protocols"}


def _registry_options(key: str) -> list[str] | None:
    """The names the registry-bounded list ``key`` may hold (``Spec.registry``), None for any other parameter:
    the studies ('*'), or the model kinds / protocols of every study whose entry reads ``key``'s section
    (``Study.section``), in registry order."""
    spec = SPECS[key]
    if not spec.registry:
        return None
    if spec.registry == "*":
        return list(STUDIES)
    field = _REGISTRY_FIELDS[spec.registry]
    studies = [s for s in STUDIES.values() if s.section == PATHS[key][0]]
    return list(dict.fromkeys(name for s in studies for name in getattr(s, field)))


def allowed_text(key: str) -> str:
    """What ``key`` may hold, in words (a registry-bounded list names the registry's names now)."""
    options = _registry_options(key)
    return SPECS[key].allowed if options is None else SPECS[key].allowed.format(options=options)


def validate(notebook: str, values: dict[str, Any]) -> Profile:
    """Check ``values`` (flat notebook names) against the schema of ``notebook``; return the typed profile.

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
        options = _registry_options(key)  # the registry's names when the check runs (a kind a test registered counts)
        if not spec.check(value) or (options is not None and not set(value) <= set(options)):
            raise ParameterError(f"{where}: parameter {_named(key)} = {value!r} is out of range; "
                                 f"allowed: {allowed_text(key)}")
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
    return build_profile(out, where)


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


BASE_KEY = "base"  # a profile's top-level key naming the profile it overrides


# params/ also holds the recipes file, which is not a profile
RECIPES_FILE = PARAMS_DIR / "protocols.yaml"


def known_profiles() -> list[str]:
    """The profiles in params/ (every YAML file there but the recipes file)."""
    return sorted(p.stem for p in PARAMS_DIR.glob("*.yaml") if p.name != RECIPES_FILE.name)


def _profile_path(profile: str | Path, relative_to: Path | None = None) -> Path:
    """``params/<name>.yaml`` for a name, else the YAML path itself (a relative one taken from
    ``relative_to``: the folder of the profile that names it as its base)."""
    path = Path(profile)
    if path.suffix not in (".yaml", ".yml"):
        return PARAMS_DIR / f"{profile}.yaml"
    return relative_to / path if relative_to is not None and not path.is_absolute() else path


def load_profile(profile: str | Path, _chain: tuple[Path, ...] = ()) -> dict[str, Any]:
    """Read ``params/<profile>.yaml`` (or a path): its sections checked against ``SCHEMA``,
    returned flat, ``{notebook name: value}``.

    A profile may name a base (``base: quick``, or a YAML path relative to its own folder) and hold
    only what it changes: its keys replace the base's (a list or a mapping value as a whole), after
    the same checks of each file's keys; the checks of every value against the notebooks that read
    it (``notebook_params``) see the merged profile. Unless it sets ``profile``, it is named after
    its file, so its results never land in the base's folder."""
    path = _profile_path(profile, _chain[-1].parent if _chain else None)
    if path.resolve() == RECIPES_FILE.resolve():
        raise ParameterError(f"{path} holds the training recipes and ablation variants (drfkit.methods.protocols), "
                             f"not a profile; known profiles: {known_profiles()}")
    if not path.is_file():
        known = known_profiles()
        named = f" (the base of {_chain[-1]})" if _chain else ""
        raise ParameterError(f"parameter file {path}{named} does not exist; known profiles: {known}")
    with open(path) as fh:
        values = yaml.safe_load(fh) or {}
    if not isinstance(values, dict):
        raise ParameterError(f"{path}: expected a mapping of parameter: value")
    base = values.pop(BASE_KEY, None)
    flat = flatten_profile(values, str(path))
    if base is None:
        return flat
    if not isinstance(base, str) or not base.strip():
        raise ParameterError(f"{path}: '{BASE_KEY}' names the profile this one overrides: a name in params/ "
                             f"(quick, paper) or a YAML path; got {base!r}")
    here = path.resolve()
    if here in _chain or _profile_path(base, path.parent).resolve() in (*_chain, here):
        cycle = " -> ".join(str(p) for p in (*_chain, here, _profile_path(base, path.parent).resolve()))
        raise ParameterError(f"{path}: the profiles' bases form a circle: {cycle}")
    return load_profile(base, (*_chain, here)) | {"profile": path.stem} | flat


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


def for_notebook(notebook: str, values: dict[str, Any]) -> Profile:
    """The validated parameters of ``notebook`` from a whole profile's values (``load_profile``,
    overrides merged): what the command-line tools use to run as that notebook would."""
    return validate(notebook, notebook_params(notebook, values))


def for_command(notebook: str, profile: str) -> Profile | None:
    """``for_notebook`` of a named profile for a command line: None after printing the
    parameter error (the command then exits with status 2)."""
    try:
        return for_notebook(notebook, load_profile(profile))
    except ParameterError as exc:
        print(f"parameter error: {exc}")
        return None
