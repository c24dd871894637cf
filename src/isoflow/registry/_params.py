"""Model parameters: :class:`Param` (kind, bounds, choices, help) and the checking of values.

A value reaches a model from a TOML file or a result file's JSON (:meth:`Param.check`) or as a
word of the command line (:meth:`Param.parse`, :func:`parse_param`, :func:`parse_params`); a
model without declared parameters gets plain TOML/JSON values (:func:`json_value`). Every
mistake is one line of :class:`ConfigError`, the error of the whole registry.
"""

from __future__ import annotations

import math
import tomllib
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from .._errors import IsoflowError

if TYPE_CHECKING:
    from ._catalogue import ModelSpec

__all__ = ["ConfigError", "Param", "choice", "json_value", "parse_param", "parse_params"]


class ConfigError(IsoflowError, ValueError):
    """A run configuration names an unknown model/method/option or has a bad value."""


_KIND_WORDS = {int: "an integer", float: "a number", str: "a string", bool: "true or false"}


@dataclass(frozen=True)
class Param:
    """A model parameter settable from the command line and from TOML.

    Attributes
    ----------
    kind : type
        ``int``, ``float``, ``str`` or ``bool`` (of each entry, with ``length``).
    default : object
        The value used when the parameter is not given; ``None`` leaves it to the model
        function's own default (the parameter is then not recorded).
    help : str
        One line for ``isoflow run --help`` and ``isoflow list models``.
    low, high : float, optional
        Inclusive bounds (of each entry). ``high`` on a size keeps a typo (``n = 100000``) from
        asking for gigabytes before anything runs; a larger system is a job for the Python API.
    choices : tuple, optional
        The allowed values.
    length : int, optional
        The parameter is a list of this many entries (``[16, 16]`` in TOML, ``16,16`` on the
        command line); the model function gets a tuple.
    """

    kind: type
    default: Any
    help: str
    low: float | None = None
    high: float | None = None
    choices: tuple[Any, ...] | None = None
    length: int | None = None

    def check(self, value: Any, what: str) -> Any:
        """``value`` (a TOML/JSON value) checked against the kind, bounds and choices.

        Parameters
        ----------
        value : object
            The value (a list of :attr:`length` values for a vector parameter).
        what : str
            Names the parameter in the messages.

        Returns
        -------
        object
            The value converted to the kind (a list for a vector parameter).

        Raises
        ------
        ConfigError
            The wrong kind or length, a non-finite float, a value out of the bounds or not
            one of the choices.
        """
        if self.length is None:
            return self._check_one(value, what)
        if not isinstance(value, list | tuple) or len(value) != self.length:
            raise ConfigError(
                f"{what} must be a list of {self.length} {self.kind.__name__} values, got {value!r}"
            )
        return [self._check_one(v, what) for v in value]

    def _check_one(self, value: Any, what: str) -> Any:
        kind = self.kind
        if kind is bool:
            ok = isinstance(value, bool | np.bool_)
            out: Any = bool(value) if ok else None
        elif kind is int:
            ok = isinstance(value, int | np.integer) and not isinstance(value, bool | np.bool_)
            out = int(value) if ok else None
        elif kind is float:
            ok = isinstance(value, int | float | np.integer | np.floating) and not isinstance(
                value, bool | np.bool_
            )
            out = float(value) if ok else None
            if ok and not math.isfinite(out):
                raise ConfigError(f"{what} must be finite, got {value!r}")
        else:
            ok = isinstance(value, str)
            out = value if ok else None
        if not ok:
            raise ConfigError(f"{what} must be {_KIND_WORDS[kind]}, got {value!r}")
        if self.choices is not None and out not in self.choices:
            raise ConfigError(
                f"{what} must be one of {', '.join(map(repr, self.choices))}, got {value!r}"
            )
        if self.low is not None and out < self.low:
            raise ConfigError(f"{what} must be >= {self.low:g}, got {value!r}")
        if self.high is not None and out > self.high:
            raise ConfigError(
                f"{what} must be <= {self.high:g}, got {value!r} (a size bound of the command "
                "line and of configuration files; build larger systems from Python)"
            )
        return out

    def parse(self, text: str, what: str) -> Any:
        """The value of a command-line word ``text`` (then :meth:`check`-ed).

        Parameters
        ----------
        text : str
            The word; a vector parameter is written ``a,b`` or ``[a,b]``.
        what : str
            Names the parameter in the messages.

        Raises
        ------
        ConfigError
            As :meth:`check`, or a malformed list.
        """
        if self.length is not None:
            body = text.strip()
            if body.startswith("[") or body.endswith("]"):
                body = body.removeprefix("[").removesuffix("]")
                if not (text.strip().startswith("[") and text.strip().endswith("]")):
                    body = ""  # unbalanced brackets
            words = [w.strip() for w in body.split(",")]
            if "" in words:
                example = self.typed(
                    self.default if self.default is not None else [self.kind(1)] * self.length
                )
                raise ConfigError(
                    f"{what} must be a list of {self.length} {self.kind.__name__} values "
                    f"written like {example}, got {text!r}"
                )
            return self.check([self._word(w) for w in words], what)
        return self.check(self._word(text), what)

    def _word(self, text: str) -> Any:
        if self.kind is str:
            return text
        try:
            if self.kind is int:
                return int(text)
            if self.kind is float:
                return float(text)
        except ValueError:
            return text  # reported by check() with the word as given
        if text.lower() in ("true", "false"):
            return text.lower() == "true"
        return text

    def value(self, checked: Any) -> Any:
        """What the model function gets for a :meth:`check`-ed value (a tuple for lists).

        Parameters
        ----------
        checked : object
            A value returned by :meth:`check`.
        """
        return tuple(checked) if self.length is not None else checked

    def kind_text(self) -> str:
        """The kind as ``isoflow list`` shows it: ``int``, or ``2-vector of int``."""
        kind = self.kind.__name__
        return kind if self.length is None else f"{self.length}-vector of {kind}"

    def typed(self, value: Any) -> str:
        """``value`` as it is typed on the command line: ``16,16``, ``0.5``, ``curve``."""
        if isinstance(value, list | tuple):
            return ",".join(self.typed(v) for v in value)
        if isinstance(value, bool):
            return "true" if value else "false"
        if self.kind is int and isinstance(value, int | float) and float(value).is_integer():
            return str(int(value))
        if isinstance(value, float):
            return f"{value:g}"
        return str(value)

    def describe(self, name: str) -> str:
        """One line for ``isoflow list``: name, kind, default, help and upper bound."""
        default = "" if self.default is None else f", default {self.typed(self.default)}"
        bound = "" if self.high is None else f" [at most {self.typed(self.high)}]"
        return f"{name} ({self.kind_text()}{default}): {self.help}{bound}"


def choice(value: Any, options: Mapping[str, Any], what: str) -> str:
    """``value`` if it is one of the names of ``options``.

    Raises
    ------
    ConfigError
        Not a string, or not a name of ``options`` (with the spelling to use when ``value``
        differs from one only by case, underscores or spaces).
    """
    if not isinstance(value, str):
        raise ConfigError(f"{what} must be a name (a string), got {value!r}")
    if value not in options:
        hint = ""
        near = value.strip().lower().replace("_", "-").replace(" ", "-")
        if near in options:
            hint = f"; write {near!r}"
        raise ConfigError(f"unknown {what} {value!r}{hint} (choose from {', '.join(options)})")
    return value


def json_value(value: Any, what: str) -> Any:
    """``value``, a parameter of a model without declared parameters, as a plain TOML/JSON
    value (what result files record): finite numbers, strings, booleans, lists and tables.

    Raises
    ------
    ConfigError
        A non-finite number, a table key that is not a string, or another type.
    """
    if isinstance(value, bool | str) or value is None:
        return value
    if isinstance(value, int | np.integer):
        return int(value)
    if isinstance(value, float | np.floating):
        if not math.isfinite(value):
            raise ConfigError(f"{what} must be finite, got {value!r}")
        return float(value)
    if isinstance(value, list | tuple):
        return [json_value(v, f"{what}[{i}]") for i, v in enumerate(value)]
    if isinstance(value, dict):
        for k in value:
            if not isinstance(k, str):
                raise ConfigError(f"{what}: table keys must be strings, got {k!r}")
        return {k: json_value(v, f"{what}.{k}") for k, v in value.items()}
    raise ConfigError(
        f"{what} must be a number, string, boolean, array or table, got {type(value).__name__}"
    )


def parse_param(spec: ModelSpec, key: str, text: str) -> Any:
    """The value of model parameter ``key`` given as command-line text.

    A declared parameter is converted to its kind (``"ten"`` for an integer is an error); for a
    model without declared parameters the text is read as a TOML value (``3`` an integer,
    ``0.5`` a float, ``true`` a boolean, ``[1, 2]`` an array), or kept as a string; text that
    starts like a TOML array, table or quoted string but does not parse is an error.

    Parameters
    ----------
    spec : ModelSpec
        The model.
    key : str
        The parameter's name.
    text : str
        The value as typed.

    Raises
    ------
    ConfigError
        A key the model does not declare, a value the declared parameter refuses, or text that
        looks like TOML but does not parse.
    """
    if spec.params is not None:
        if key not in spec.params:
            known = ", ".join(spec.params) or "none"
            raise ConfigError(f"model {spec.name!r} has no parameter {key!r} (parameters: {known})")
        return spec.params[key].parse(text, f"{spec.name} {key}")
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError as exc:
        if text.strip()[:1] in ("[", "{", '"', "'"):  # meant as a TOML list, table or string
            raise ConfigError(
                f"--param {key}: {text!r} is not a TOML value ({' '.join(str(exc).split())}); "
                'write a list as [1, 2], a table as {a = 1}, a string as "text"'
            ) from None
        return text  # a plain word: the string itself


def parse_params(spec: ModelSpec, texts: Iterable[tuple[str, str]]) -> dict[str, Any]:
    """The model parameters given as command-line words: ``(key, text)`` pairs, in order.

    Each text is read by :func:`parse_param`; a key given twice keeps its last value (an
    option later on the command line overrides an earlier one).

    Parameters
    ----------
    spec : ModelSpec
        The model.
    texts : iterable of (str, str)
        The ``(key, text)`` pairs, in command-line order.

    Returns
    -------
    dict
        Parameter name to value.
    """
    return {key: parse_param(spec, key, text) for key, text in texts}
