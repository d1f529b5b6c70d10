"""The profile's schema: every parameter's section, type, allowed values and check, in one place.

The YAML profiles in ``params/`` are nested by section (``pendulum:``, ``pendulum.book:``,
``pedestrians:``, ...). ``SCHEMA`` is that layout; ``drfkit.study.profile`` turns it into the typed
profile the study and book layers read (``P.pendulum.book.epochs``), and ``drfkit.study.params``
validates a profile against it. Notebooks see one flat name per parameter, because papermill
injects top-level variables: a section's prefix plus the key (``pendulum.book.epochs`` is
``pend_book_epochs``); ``SPECS`` and ``PATHS`` map those names to their specs and paths.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable, get_origin

from drfkit.methods.protocols import ABLATION_BUDGETS, PROTOCOLS, VARIANTS


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
    # a list bounded by the registry (drfkit.study.registry), checked by drfkit.study.params when it validates,
    # so that a kind registered later (by a test, say) is accepted: 'kinds' / 'protocols' for the model kinds
    # (``Study.kinds``) / training protocols (``Study.all_protocols``) of the studies whose entry reads the
    # parameter's section (``Study.section``), '*' for the studies themselves; ``allowed`` then says where the
    # names go ('{options}'). No study is named here: the registry says which study a section is.
    registry: str = ""

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


def _nonempty(v: list) -> bool:
    return len(v) > 0


def _names(v: list[str]) -> bool:
    return len(v) > 0 and len(set(v)) == len(v)


def _paper_protocols(v: list[str]) -> bool:
    """Training protocols: the paper's among them, without repeats (the registry bounds the names)."""
    return "paper" in v and _names(v)


def _restarts(v: dict) -> bool:
    """{kind: {slot seed: training seed}}: kinds of the book's protocol, seeds integers >= 0, no slot its own."""
    def seeds(m) -> bool:
        return isinstance(m, dict) and all(isinstance(k, int) and isinstance(t, int) and 0 <= k != t >= 0
                                           for k, t in m.items()) and len(set(m.values())) == len(m)
    return all(kind in PROTOCOLS["book"] and seeds(m) for kind, m in v.items())


_POSITIVE = ("an integer >= 1", lambda v: v >= 1)
_RATE = ("a number in (0, 1)", lambda v: 0 < v < 1)
_LEVELS = "a non-empty list of numbers in [0, 1]"
_SEEDS = "a non-empty list of distinct integers >= 0"
_PROTOCOLS = "a non-empty subset of {options} that holds 'paper', without repeats"

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
        "sweep_sequences": Spec(int, *_POSITIVE,
                                "test sequences (the first N) at the sweep's levels other than eval_max_noise: no claim "
                                "reads them, so they are shown with their seed intervals on fewer sequences"),
        "data_seed": Spec(int, "an integer >= 0", lambda v: v >= 0),
        "test_seed": Spec(int, "an integer >= 0, neither data_seed nor data_seed + 1", lambda v: v >= 0,
                          "the test split's own seed: a fresh one makes a test set no selection step has read"),
        "models": Spec(list[str], "a non-empty subset of {options}", _nonempty, registry="kinds"),
        "epochs": Spec(int, *_POSITIVE),
        "batch_size": Spec(int, *_POSITIVE),
        "lr": Spec(float, *_RATE),
        "patience": Spec(int, "an integer >= 0 (0 = train every epoch)", lambda v: v >= 0,
                         "stop a run after this many epochs without a better validation NLL"),
        "protocols": Spec(list[str], _PROTOCOLS, _paper_protocols,
                          "the training protocols notebooks 01 and 02 train and evaluate (drfkit.methods.protocols)",
                          registry="protocols"),
        "book": Section("book_", {
            "models": Spec(list[str], "a non-empty list of model kinds the book's protocol names "
                           "(drfkit.methods.protocols.PROTOCOLS['book'])",
                           lambda v: len(v) > 0 and len(set(v)) == len(v) and set(v) <= set(PROTOCOLS["book"]),
                           "the models trained under the book's protocol (it adds the known-dynamics filter)"),
            "epochs": Spec(int, *_POSITIVE, "epochs of the book's protocol"),
            "batch_size": Spec(int, *_POSITIVE),
            "lr": Spec(float, *_RATE),
            "patience": Spec(int, "an integer >= 0 (0 = train every epoch)", lambda v: v >= 0,
                             "stop a book-protocol run after this many epochs without a better validation NLL"),
            "restarts": Spec(dict, "a mapping from a model kind to {seed: the seed it is trained from instead}, "
                             "e.g. {known_dynamics: {1: 3}}; {} for none", _restarts,
                             "the validation-only restart rule's replacements: the run in a seed's slot trains from "
                             "another seed (drfkit.study.pendulum_runs.training_seed)"),
        }, "the book's training protocol (drfkit.methods.protocols)"),
    }, "the noisy pendulum: data, then training under the paper's protocol"),
    "dynamics": Section("", {
        "reference_particles": Spec(int, "an integer >= 10", lambda v: v >= 10,
                                    "particles of the true-physics reference (drfkit.methods.references)"),
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
            "round3": Section("round3_", {
                "budget": Spec(str, f"one of {list(ABLATION_BUDGETS)}", lambda v: v in ABLATION_BUDGETS,
                               "budget of the third round: competence, trained without pure-noise frames "
                               "(drfkit.methods.protocols.ROUND3_VARIANTS)"),
                "variants": Spec(list[str], f"a non-empty subset of {list(VARIANTS)}", _subset(VARIANTS)),
                "seeds": Spec(list[int], _SEEDS, _seeds),
            }),
        }),
        "limit": Section("limit_", {
            "sequences": Spec(int, *_POSITIVE, "test sequences the limit on pixels is computed on "
                                               "(drfkit.methods.pixel_bayes; the first of the test split)"),
            "particles": Spec(list[int], "a non-empty list of increasing integers >= 10",
                              lambda v: len(v) > 0 and all(x >= 10 for x in v) and list(v) == sorted(set(v)),
                              "particle counts of the pixel filter; the largest gives the table, all show convergence"),
        }),
        "regime": Section("regime_", {
            "train_noise": Spec(list[float], "a non-empty list of distinct numbers in [0, 1] that holds 0.5",
                                lambda v: 0.5 in v and all(map(_in01, v)) and len(set(v)) == len(v),
                                "max noise levels the noise-regime map trains at (drfkit.study.regime; 0.5 is the "
                                "book's own protocol, others are drfkit.methods.protocols.regime_variant)"),
            "seeds": Spec(list[int], _SEEDS, _seeds),
            "test_sequences": Spec(int, *_POSITIVE, "sequences of the regime map's own test split (every level)"),
        }),
    }, "notebook 02's dynamics study"),
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
        "models": Spec(list[str], "a non-empty subset of {options}", _nonempty, registry="kinds"),
        "epochs": Spec(int, *_POSITIVE),
        "batch_size": Spec(int, *_POSITIVE),
        "lr": Spec(float, *_RATE),
        "protocols": Spec(list[str], _PROTOCOLS, _paper_protocols,
                          "the training protocols notebook 03 trains and notebooks 04 and 06 judge "
                          "(drfkit.methods.protocols.PEDESTRIAN_PROTOCOLS; Monoloco's runs are shared)",
                          registry="protocols"),
    }, "pedestrian depth: data (simulated or nuScenes + PifPaf), then the DRF family's training"),
    "monoloco": Section("monoloco_", {
        "epochs": Spec(int, *_POSITIVE),
        "batch_size": Spec(int, *_POSITIVE),
        "lr": Spec(float, *_RATE),
    }, "Monoloco's own schedule"),
    "evaluation": Section("eval_", {
        "studies": Spec(list[str], "a non-empty subset of {options}, without repeats", _names,
                        "which studies notebooks 04 and 06 evaluate (both, unless one's models are not trained "
                        "yet: its claims are then listed as not evaluated)", registry="*"),
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
        "paired_rounds": Spec(int, "an integer >= 2", lambda v: v >= 2,
                              "interleaved rounds of claim C6's pair (Monoloco as published, the DRF's sequential "
                              "passes; batch 1, one thread): the claim's interval is over the per-round ratios"),
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



def flat_name(*path: str) -> str:
    """The notebook (flat) name of the parameter at ``path``: ``flat_name("pendulum", "book", "epochs")`` is
    'pend_book_epochs'. Checkpoint and cache hashes name parameters this way, so they outlive the layout."""
    try:
        return _BY_PATH[".".join(path)]
    except KeyError:
        raise ParameterError(f"no parameter at {'.'.join(path)!r}; known: {sorted(_BY_PATH)}") from None


__all__ = ["flat_name", "ParameterError", "Spec", "Section", "SCHEMA", "SPECS", "PATHS"]
