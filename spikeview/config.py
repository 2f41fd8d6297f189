"""Settings are data: typed configs that save to TOML and load back unchanged.

Derive a ``@dataclass`` from :class:`Config`; fields must be TOML-representable (bool, int, float,
str, lists/tuples of those, nested :class:`Config` dataclasses, or ``None``, which is stored by
omission). ``Config.from_dict`` rejects unknown keys and wrong types with a sentence naming the key.

**A settable parameter is declared once, on its field**: ``k: float = param(20.0, label=…, help=…,
lo=0, hi=1000)`` keeps its command-line flag, app control, label, unit, range and help in the field's
metadata (:class:`ParamMeta`). The recipe's view table (:data:`spikeview.recipe.PARAMS`), the CLI
flags, the app's controls, the README table and the range check (:meth:`Config.check_params`, the
one validation path, with :func:`check_value`) are all generated from it.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import os
import tomllib
import types
import typing
from pathlib import Path
from typing import Any, TypeVar

from spikeview.errors import InputFileError, ParameterError

C = TypeVar("C", bound="Config")


@dataclasses.dataclass(frozen=True)
class ParamMeta:
    """What a field declared with :func:`param` knows about itself (its ``metadata["param"]``).

    Attributes:
        label: the app control's label and the name used in the app's messages.
        help: one sentence, with the unit.
        flag: command-line flag (``None``: ``--`` and the field name with dashes; ``""``: no flag).
        key: the app's control (session parameter name; ``None``: the field name; ``""``: not in the app).
        unit: unit shown beside numbers (``ticks``, ``fps``…).
        lo, hi: accepted range (``None`` = unbounded); ``lo_open`` excludes ``lo``.
        step: slider/spin step in the app.
        choices: accepted strings.
    """

    label: str
    help: str
    flag: str | None = None
    key: str | None = None
    unit: str = ""
    lo: float | None = None
    hi: float | None = None
    lo_open: bool = False
    step: float | None = None
    choices: tuple[str, ...] = ()


def param(default: Any, *, label: str, help: str, flag: str | None = None, key: str | None = None, unit: str = "",
          lo: float | None = None, hi: float | None = None, lo_open: bool = False, step: float | None = None,
          choices: tuple[str, ...] = ()) -> Any:
    """A dataclass field that a person sets (see the module docstring); ``default`` is its default."""
    meta = ParamMeta(label, help, flag, key, unit, lo, hi, lo_open, step, tuple(choices))
    return dataclasses.field(default=default, metadata={"param": meta})


def param_fields(cls: type) -> list[tuple[str, ParamMeta]]:
    """``(field name, metadata)`` of every :func:`param` field of a config class, in field order."""
    return [(f.name, f.metadata["param"]) for f in dataclasses.fields(cls) if "param" in f.metadata]


def check_value(name: str, kind: Any, value: Any, lo: float | None = None, hi: float | None = None,
                choices: tuple[str, ...] = (), *, lo_open: bool = False, unit: str = "") -> Any:
    """``value`` converted to ``kind`` (bool, str, int or float) and checked against the range or
    choices; :class:`ParameterError` naming ``name`` (the word the person typed) otherwise."""
    if kind is bool:
        if not isinstance(value, bool):
            raise ParameterError(f"{name} must be true or false, got {value!r}.")
        return value
    if kind is str:
        value = str(value)
        if choices and value not in choices:
            raise ParameterError(f"{name} = {value!r} is not valid: use one of {', '.join(choices)}.")
        return value
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(float(value)):
        raise ParameterError(f"{name} must be a finite number, got {value!r}.")
    if kind is int:
        if float(value) != int(value):
            raise ParameterError(f"{name} must be a whole number, got {value!r}.")
        value = int(value)
    else:
        value = float(value)
    bad_lo = lo is not None and (value <= lo if lo_open else value < lo)
    bad_hi = hi is not None and value > hi
    if bad_lo or bad_hi:
        lo_s = "" if lo is None else (f"> {lo:g}" if lo_open else f">= {lo:g}")
        hi_s = "" if hi is None else f"<= {hi:g}"
        rng = " and ".join(x for x in (lo_s, hi_s) if x)
        raise ParameterError(f"{name} = {value:g} is out of range: use a value {rng}{' ' + unit if unit else ''}.")
    return value


@functools.lru_cache(maxsize=None)
def _type_hints(cls: type) -> dict[str, Any]:
    """``typing.get_type_hints(cls)``, once per class: it evaluates every annotation string each call (~1 ms a
    class), and every config built checks every field (the app builds its recipe on the GUI thread; issue 15)."""
    return typing.get_type_hints(cls)


def field_kind(cls: type, name: str) -> tuple[Any, bool]:
    """``(type, optional)`` of a config field: ``int | None`` gives ``(int, True)``."""
    tp = _type_hints(cls)[name]
    if typing.get_origin(tp) in (typing.Union, types.UnionType):
        args = [a for a in typing.get_args(tp) if a is not type(None)]
        return (args[0] if len(args) == 1 else tp), type(None) in typing.get_args(tp)
    return tp, False


def _strip_none(value: Any) -> Any:
    if isinstance(value, dict):
        return {k: _strip_none(v) for k, v in value.items() if v is not None}
    if isinstance(value, (list, tuple)):
        return [_strip_none(v) for v in value]
    if isinstance(value, Path):
        return str(value)
    return value


def _coerce(name: str, tp: Any, value: Any, where: str) -> Any:
    origin = typing.get_origin(tp)
    if origin in (typing.Union, types.UnionType):
        args = [a for a in typing.get_args(tp) if a is not type(None)]
        if value is None:
            return None
        errors = []
        for a in args:
            try:
                return _coerce(name, a, value, where)
            except ParameterError as e:  # try the next member of the union
                errors.append(e)
        raise errors[-1]
    if isinstance(tp, type) and issubclass(tp, Config):
        if not isinstance(value, dict):
            raise ParameterError(f"{where}: '{name}' must be a table, got {value!r}; fix the settings file.")
        return tp.from_dict(value, where=f"{where} [{name}]")
    if origin in (list, tuple):
        if not isinstance(value, (list, tuple)):
            raise ParameterError(f"{where}: '{name}' must be a list, got {value!r}; fix the settings file.")
        (inner, *_rest) = typing.get_args(tp) or (Any,)
        items = [_coerce(name, inner, v, where) for v in value]
        return tuple(items) if origin is tuple else items
    if tp is Any:
        return value
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ParameterError(f"{where}: '{name}' must be a number, got {value!r}; fix the settings file.")
        return float(value)
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ParameterError(f"{where}: '{name}' must be an integer, got {value!r}; fix the settings file.")
        return value
    if tp is bool:
        if not isinstance(value, bool):
            raise ParameterError(f"{where}: '{name}' must be true or false, got {value!r}; fix the settings file.")
        return value
    if tp is str:
        if not isinstance(value, str):
            raise ParameterError(f"{where}: '{name}' must be a string, got {value!r}; fix the settings file.")
        return value
    if origin is dict or tp is dict:
        if not isinstance(value, dict):
            raise ParameterError(f"{where}: '{name}' must be a table, got {value!r}; fix the settings file.")
        return dict(value)
    return value


@dataclasses.dataclass
class Config:
    """Base class of every settings dataclass (see module docstring)."""

    #: the recipe table this config is (``"guided"``): names parameters in messages (``guided.k``)
    TABLE: typing.ClassVar[str] = ""

    def check_params(self) -> None:
        """Check every :func:`param` field against its declared range or choices (the one validation
        path of the parameters; configs call it from ``__post_init__``)."""
        for name, meta in param_fields(type(self)):
            value = getattr(self, name)
            kind, optional = field_kind(type(self), name)
            path = f"{self.TABLE}.{name}" if self.TABLE else name
            if value is None:
                if optional:
                    continue
                raise ParameterError(f"{path} needs a value; see --help for its range.")
            check_value(path, kind, value, meta.lo, meta.hi, meta.choices, lo_open=meta.lo_open, unit=meta.unit)

    def to_dict(self) -> dict[str, Any]:
        """A plain dict (TOML-ready: ``None`` values omitted, tuples as lists)."""
        return _strip_none(dataclasses.asdict(self))

    @classmethod
    def from_dict(cls: type[C], data: dict[str, Any], where: str | None = None) -> C:
        """Build from a dict, rejecting unknown keys and wrong types with a clear sentence."""
        where = where or cls.__name__
        hints = typing.get_type_hints(cls)
        names = {f.name for f in dataclasses.fields(cls) if f.init}
        unknown = sorted(set(data) - names)
        if unknown:
            raise ParameterError(
                f"{where}: unknown setting(s) {', '.join(unknown)}; valid ones are {', '.join(sorted(names))}."
            )
        kwargs = {k: _coerce(k, hints[k], v, where) for k, v in data.items()}
        try:
            obj = cls(**kwargs)
        except ParameterError:
            raise
        except (TypeError, ValueError) as e:
            raise ParameterError(f"{where}: {e}") from None
        return obj

    def replace(self: C, **changes: Any) -> C:
        return dataclasses.replace(self, **changes)

    def to_toml(self) -> str:
        import tomli_w

        return tomli_w.dumps(self.to_dict())

    def save(self, path: str | os.PathLike[str]) -> Path:
        """Write as TOML atomically (temporary name, then rename)."""
        path = Path(path)
        text = self.to_toml()
        from spikeview._files import write_atomic

        return write_atomic(path, text, "the settings")

    @classmethod
    def load(cls: type[C], path: str | os.PathLike[str], table: str | None = None) -> C:
        """Read a TOML file (optionally one ``[table]`` of it) written by :meth:`save`."""
        data = load_toml(path)
        if table is not None:
            if table not in data:
                raise ParameterError(f"{path}: no [{table}] table; it holds {', '.join(data) or 'nothing'}.")
            data = data[table]
        return cls.from_dict(data, where=str(path))


def load_toml(path: str | os.PathLike[str]) -> dict[str, Any]:
    """Read a TOML file with errors that name the file."""
    from spikeview._files import existing_file

    path = existing_file(path, "settings file", "give the path of a .toml file")
    try:
        with open(path, "rb") as f:
            return tomllib.load(f)
    except OSError as e:
        raise InputFileError(f"{path}: cannot be read ({e.strerror or e}); check the path and its permissions.") from None
    except tomllib.TOMLDecodeError as e:
        raise InputFileError(f"{path}: not valid TOML ({e}); fix or delete the file.") from None
    except UnicodeDecodeError:
        raise InputFileError(f"{path}: not a text TOML file; point to a settings file written by spikeview.") from None


def check_range(name: str, value: float, lo: float, hi: float, *, lo_open: bool = False) -> None:
    """Raise :class:`ParameterError` unless ``lo <= value <= hi`` (``lo < value`` when ``lo_open``), finite."""
    bad = not math.isfinite(value) or value > hi or (value <= lo if lo_open else value < lo)
    if bad:
        lo_s = f"> {lo:g}" if lo_open else f">= {lo:g}"
        hi_s = "" if math.isinf(hi) else f" and <= {hi:g}"
        raise ParameterError(f"{name} = {value!r} is out of range: use a number {lo_s}{hi_s}.")
