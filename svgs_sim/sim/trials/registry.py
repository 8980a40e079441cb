"""The trial-kind registry: a kind's declaration (:class:`TrialKind`, its numeric :class:`Parameter` s
and columns), registering one by name and finding it again (importing the modules that register
more).

Part of :mod:`svgs_sim.sim.trials`.
"""

from __future__ import annotations

import importlib
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Callable, Hashable

import numpy as np

from svgs_sim.base.errors import InputError


#: Modules that may register more trial kinds; imported when an unknown name is asked for
#: (a module that is not installed is skipped). The render-and-solve trial of the campaign,
#: the sensitivity study, the range sweep and the exposure study registers itself from
#: ``svgs_sim.sim.render_trial``. Studies run the trials with :func:`svgs_sim.studies.execution.run_task`.
KIND_MODULES = ("svgs_sim.sim.render_trial", "svgs_sim.sim.tof_trial")


#: Columns every study row has besides the scenario and the kind's outputs.
ID_COLUMNS = ("trial_id", "seed")


TIMING_COLUMNS = ("wall_s", "cpu_s")


def _number(x) -> str:
    """``x`` for a message: a whole number in full (a seed, samples per pixel), else ``:g``."""
    if x is None:
        return ""
    x = float(x)
    return str(int(x)) if x.is_integer() and abs(x) < 1e15 else f"{x:g}"


@dataclass(frozen=True)
class Code:
    """A value of a parameter that stands for a choice, not a quantity: what the results store
    holds (``value``) and what a user writes and reads (``word``).

    Attributes
    ----------
    value : float
        The number in the store's row (``-1.0`` for the profile's f-number...): the codec's, never
        shown in a message.
    word : str
        What ``--fixed NAME=WORD`` takes and messages print (``profile``, ``renderer``, ``phone``,
        ``app``, ``otsu``...).
    meaning : str
        What it chooses, for ``--help`` and messages (``the profile's [optics] f_number``).
    """

    value: float
    word: str
    meaning: str


@dataclass(frozen=True)
class Parameter:
    """A scenario parameter a study may set or vary.

    Attributes
    ----------
    name : str
        Scenario key (units in the name).
    unit : str
    meaning : str
        One sentence for reports and ``--help``.
    default : float
    needs_render : bool
        True if changing it changes the rendered flux (geometry, optics, flash); False if
        it acts after the render (noise, exposure, detector, calibration used by the solver),
        so trials differing only in it can share one render.
    lower, upper : float or None
        Physical domain (inclusive unless ``*_open``). Both None with ``codes``: a choice among
        the codes only (the demosaic).
    codes : tuple of Code
        Values that stand for a choice (the profile's value, the renderer's default, the app's
        threshold): written and shown as words, held in the store's row as their numbers.
    optional : bool
        The parameter does not apply to every scenario of its kind (``range_m`` and ``rail_m``:
        a trial has one of them, by its mount): ``None`` (an empty cell in the store; NaN in a
        table) means "not given", and the kind's scenario says when it must be given.
    """

    name: str
    unit: str
    meaning: str
    default: float | None
    needs_render: bool
    lower: float | None = None
    upper: float | None = None
    lower_open: bool = False
    codes: tuple = ()
    optional: bool = False

    @property
    def choice_only(self) -> bool:
        """A choice among :attr:`codes` (no physical range)."""
        return bool(self.codes) and self.lower is None and self.upper is None

    def physical_domain(self) -> str:
        """The physical values in words, with the unit (none for a dimensionless "1")."""
        unit = "" if self.unit in ("", "1") else f" {self.unit}"
        lo, hi = _number(self.lower), _number(self.upper)
        if self.lower is not None and self.upper is not None:
            if self.lower_open:
                return f"a value > {lo} and <= {hi}{unit}"
            return f"{lo} to {hi}{unit}"
        if self.lower is not None:
            return f"a value {'>' if self.lower_open else '>='} {lo}{unit}"
        if self.upper is not None:
            return f"a value <= {hi}{unit}"
        return f"a finite number{unit}"

    def domain(self, codes: bool = True) -> str:
        """The allowed values in words: the physical range and (``codes``) the words."""
        words = ", ".join(f"{c.word!r} ({c.meaning})" for c in self.codes)
        if self.choice_only:
            return f"one of {words}"
        if not codes or not self.codes:
            return self.physical_domain()
        return f"{self.physical_domain()}, or {words}"

    def word(self, value) -> str:
        """``value`` as a user reads it: the word of a code, else the number."""
        for c in self.codes:
            if float(value) == c.value:
                return c.word
        return _number(value)

    def check(self, value, what: str = "", *, codes: bool = True) -> float | None:
        """The row's number of ``value`` (a number in the domain, or - with ``codes`` - a code's
        word or the code's number, as a store holds it), else :class:`InputError`.

        Parameters
        ----------
        value : float, str or None
            None (or NaN, an empty cell read into a table) only where the parameter is
            :attr:`optional`; it is returned as None.
        what : str
            The input's name for the message (default the parameter's).
        codes : bool
            Accept the codes (False: a quantity only, e.g. the bounds of a varied range).
        """
        label = what or self.name
        if self.optional and (value is None or (isinstance(value, (float, np.floating)) and np.isnan(value))):
            return None
        if isinstance(value, str) and codes:
            for c in self.codes:
                if value.strip().lower() == c.word:
                    return float(c.value)
        try:
            v = float(value)
        except (TypeError, ValueError):
            raise InputError(f"{label}: expected {self.domain(codes)}, got {value!r}") from None
        if not np.isfinite(v):
            raise InputError(f"{label}: expected {self.domain(codes)}, got {value!r}")
        if codes and any(v == c.value for c in self.codes):
            return v
        if self.choice_only:
            what_ = "it is a choice, not a quantity: hold it fixed" if not codes else self.meaning
            raise InputError(f"{label}: expected {self.domain()}, got {_number(v)} - {what_}")
        low_bad = self.lower is not None and (v < self.lower or (self.lower_open and v == self.lower))
        if low_bad or (self.upper is not None and v > self.upper):
            raise InputError(f"{label}: expected {self.domain(codes)}, got {v:g} - {self.meaning}")
        return v


@dataclass(frozen=True)
class TrialKind:
    """A registered kind of trial.

    Attributes
    ----------
    name : str
    run_trial : callable
        ``run_trial(scenario: dict, seed: int) -> dict`` (top-level, picklable). The dict
        holds the kind's ``outputs``.
    outputs : tuple of str
        Output columns, in order.
    parameters : mapping of str -> Parameter
        Numeric scenario parameters (for validation and sensitivity studies).
    text_keys : tuple of str
        Non-numeric scenario keys (camera, pattern...).
    run_group : callable, optional
        ``run_group(scenarios, seeds) -> list[dict]`` for trials sharing one render key.
    render_key : callable, optional
        ``render_key(scenario) -> hashable``.
    warm_up : callable, optional
        Called once per worker process (JIT compilation, caches).
    description : str
    module : str
        Module that registers the kind; workers import it to find the kind.
    scenario_type : type, optional
        The kind's typed scenario (a :class:`TrialScenario` subclass): :func:`build_scenario`
        makes one; without it a scenario is a plain dict of row values.
    """

    name: str
    run_trial: Callable[[dict, int], dict]
    outputs: tuple
    parameters: Mapping[str, Parameter]
    text_keys: tuple = ("camera", "pattern")
    run_group: Callable | None = None
    render_key: Callable[[dict], Hashable] | None = None
    warm_up: Callable | None = None
    description: str = ""
    module: str = field(default="")
    scenario_type: type | None = None

    @property
    def ref(self) -> tuple[str, str]:
        return (self.module or self.run_trial.__module__, self.name)

    def columns(self, scenario_keys) -> list[str]:
        """All columns of a study of this kind whose scenarios have ``scenario_keys``."""
        clash = set(scenario_keys) & (set(self.outputs) | set(ID_COLUMNS) | set(TIMING_COLUMNS))
        if clash:
            raise ValueError(f"scenario keys {sorted(clash)} clash with output columns")
        return [*ID_COLUMNS, *scenario_keys, *self.outputs, *TIMING_COLUMNS]


_REGISTRY: dict[str, TrialKind] = {}


def register_trial_kind(kind: TrialKind) -> TrialKind:
    """Register (or replace) a trial kind under ``kind.name``."""
    if not kind.module:
        kind = TrialKind(**{**kind.__dict__, "module": kind.run_trial.__module__})
    _REGISTRY[kind.name] = kind
    return kind


def known_trial_kinds() -> list[str]:
    """Names of the registered trial kinds (the built-in ones of :data:`KIND_MODULES` included)."""
    _import_kind_modules()
    return sorted(_REGISTRY)


def _import_kind_modules() -> None:
    for m in KIND_MODULES:
        try:
            importlib.import_module(m)
        except ModuleNotFoundError as exc:
            if exc.name and (exc.name == m or m.startswith(exc.name + ".")):
                continue
            raise


def get_trial_kind(name: str) -> TrialKind:
    """The trial kind called ``name`` (:class:`InputError` listing the known ones)."""
    if name not in _REGISTRY and name not in known_trial_kinds():
        raise InputError(f"--trial-kind: unknown trial kind {name!r}; known: {', '.join(known_trial_kinds())}")
    return _REGISTRY[name]
