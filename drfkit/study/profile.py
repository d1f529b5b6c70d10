"""The typed profile: ``SCHEMA``'s sections as frozen dataclasses, what the study and book layers read.

    P = for_notebook("01_pendulum_training", load_profile("paper"))   # drfkit.study.params
    P.pendulum.book.epochs        # 40: int, validated against its Spec
    P.dynamics.ablation.round2.seeds
    P.as_dict()                   # {'pend_book_epochs': 40, ...}: the flat names papermill injects

One class per section of ``drfkit.study.schema.SCHEMA``, generated from it so that a parameter's
name, type and place are written once (``Profile``, ``PendulumSection``, ``PendulumBookSection``,
``DynamicsAblationRound2Section``, ...). A notebook or command declares a subset of the parameters
(``drfkit.study.params.NOTEBOOKS``); the others are absent, and reading one is an error that names
the notebook, the parameter and where to declare it, never a silent default. The flat names exist
only at the papermill boundary (``build_profile`` takes them, ``Profile.as_dict`` gives them back).
"""
from __future__ import annotations

import dataclasses
from typing import Any

from drfkit.study.schema import PATHS, SCHEMA, ParameterError, Section


class _Absent:
    """A parameter the notebook or command does not declare."""

    def __repr__(self) -> str:
        return "<not declared>"

    def __reduce__(self) -> str:
        return "ABSENT"  # unpickled as the module's one instance, so ``is ABSENT`` holds in a grid worker


ABSENT = _Absent()


class ProfileSection:
    """Base of every generated section class: reading a parameter the holder did not declare raises."""

    def __getattribute__(self, name: str) -> Any:
        value = object.__getattribute__(self, name)
        if value is ABSENT:
            where = object.__getattribute__(self, "_where")
            path = ".".join((*object.__getattribute__(self, "_path"), name))
            flat = next(n for n, p in PATHS.items() if ".".join(p) == path)
            raise ParameterError(f"{where} does not declare parameter {flat!r} [{path}]; add it to that "
                                 "notebook's list in drfkit.study.params.NOTEBOOKS (or COMMANDS)")
        return value

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.declared()})"

    def declared(self) -> dict[str, Any]:
        """{flat name: value} of every declared parameter in this section and the ones below it."""
        out: dict[str, Any] = {}
        for f in dataclasses.fields(self):
            value = object.__getattribute__(self, f.name)
            if isinstance(value, ProfileSection):
                out |= value.declared()
            elif value is not ABSENT:
                path = (*object.__getattribute__(self, "_path"), f.name)
                out[next(n for n, p in PATHS.items() if p == path)] = value
        return out


def _class_name(path: tuple[str, ...]) -> str:
    return "Profile" if not path else "".join(part.title().replace("_", "") for part in path) + "Section"


def _make_class(section: Section, path: tuple[str, ...]) -> type:
    fields = []
    for key, item in section.keys.items():
        if isinstance(item, Section):
            fields.append((key, _make_class(item, path + (key,)), dataclasses.field(default=None)))
        else:
            fields.append((key, item.type, dataclasses.field(default=ABSENT)))
    cls = dataclasses.make_dataclass(_class_name(path), fields, bases=(ProfileSection,), frozen=True,
                                     repr=False, eq=False,
                                     namespace={"__doc__": section.doc or f"the profile's {'.'.join(path)} section",
                                                "__module__": __name__})
    globals()[cls.__name__] = cls  # importable by name, so a profile pickles (grid workers get one)
    SECTION_CLASSES[path] = cls
    return cls


SECTION_CLASSES: dict[tuple[str, ...], type] = {}
Profile = _make_class(SCHEMA, ())


def _as_dict(self) -> dict[str, Any]:
    """{flat notebook name: value} of every declared parameter (what papermill injects, what a manifest records)."""
    return self.declared()


Profile.as_dict = _as_dict


def build_profile(flat: dict[str, Any], where: str) -> Any:
    """The typed profile of validated flat values ``{notebook name: value}`` (``drfkit.study.params.validate``
    calls this); ``where`` ('notebook 01_pendulum_training', 'python -m drfkit bench') names the holder in
    the error a read of an undeclared parameter raises."""
    unknown = sorted(set(flat) - set(PATHS))
    if unknown:
        raise ParameterError(f"{where}: unknown parameter(s) {unknown}")
    values: dict[tuple[str, ...], dict[str, Any]] = {}
    for name, value in flat.items():
        *sections, key = PATHS[name]
        values.setdefault(tuple(sections), {})[key] = value

    def make(path: tuple[str, ...]) -> Any:
        cls = SECTION_CLASSES[path]
        kwargs = dict(values.get(path, {}))
        for f in dataclasses.fields(cls):
            if (*path, f.name) in SECTION_CLASSES:
                kwargs[f.name] = make((*path, f.name))
        obj = cls(**kwargs)
        object.__setattr__(obj, "_where", where)
        object.__setattr__(obj, "_path", path)
        return obj

    return make(())


def narrowed(P, names, where: str) -> Any:
    """``P`` with only the declared parameters ``names`` (flat notebook names), its other ones absent.

    A cached study (``drfkit.book.measurements``) keys a profile by its declared parameters, so two notebooks
    that declare different sets miss each other's entry for the same computation; called with the profile
    narrowed to what it reads, the study keys alike in both. A read of anything else raises (it names
    ``where``), so a narrowing too tight fails loudly rather than reusing a stale result."""
    declared = P.declared()
    missing = sorted(set(names) - set(declared))
    if missing:
        raise ParameterError(f"{where}: the profile does not declare {missing}, which this computation reads")
    return build_profile({name: declared[name] for name in names}, where)


__all__ = ["ABSENT", "Profile", "ProfileSection", "SECTION_CLASSES", "build_profile", "narrowed"]
