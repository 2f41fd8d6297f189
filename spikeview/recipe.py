"""The recipe: the one settings tree behind the CLI, the app, presets and every output.

A :class:`Recipe` has five tables, each a typed :class:`~spikeview.config.Config`; its TOML is the
preset file (``<out>.preset.toml`` beside every CLI output, File ▸ Save preset… in the app)::

    [run]        which windows and which method     (RunTable: method, at, range)
    [stream]     how the capture is read             (StreamTable: format, size, CFA, flips, tick rate)
    [classical]  the observation and TFP/TFI         (ClassicalConfig: window Δτ, demosaic, colour cast, η, α)
    [guided]     the SpikeDiff sampler               (GuidedConfig, minus the observation fields)
    [export]     how frames are written              (ExportConfig: fps, levels, curve, codecs)

**One home per parameter.** The observation parameters the guided sampler shares with the
classical methods (:data:`SHARED`: the window Δτ, the demosaic, the colour-cast switch, η, α) live
in ``[classical]`` only; :class:`Recipe` copies them into its ``guided`` config, and a ``[guided]``
table that repeats one with another value is refused.

**Each parameter declared once.** A settable field is declared on its config with
:func:`~spikeview.config.param` (label, help, unit, range, choices; flag and app key when they differ
from the field's name). :data:`PARAMS` is generated from those fields: every parameter by dotted
path (``guided.k``) with its command-line flag (``--k``), its app control (the session key ``k``),
label, unit, range and one-sentence help. The CLI's flags (:func:`add_flags`, :func:`apply_flags`),
the app's controls (:mod:`spikeview.session.model`), the README table (:func:`markdown_table`) and the
configs' range checks (:meth:`~spikeview.config.Config.check_params`) all come from it; nothing else
translates names. A new parameter is its field and the code that uses it.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

from spikeview.classical.config import ClassicalConfig
from spikeview.config import Config, ParamMeta, check_value, load_toml, param, param_fields
from spikeview.errors import InputFileError, ParameterError
from spikeview.io.source import FORMATS  # the file formats: one list (spikeview.io.source)
from spikeview.export.settings import ExportConfig
from spikeview.guided.config import GuidedConfig

#: ``[classical]`` field → the ``GuidedConfig`` field it sets (the observation both methods share)
SHARED: dict[str, str] = {"window": "window", "demosaic": "demosaic", "eta": "eta", "alpha": "alpha",
                          "alpha_max_windows": "alpha_max_windows"}
#: ``GuidedConfig`` fields derived from ``[classical]`` or the sequence (never written in ``[guided]``)
DERIVED_GUIDED = tuple(SHARED.values()) + ("use_cast", "balance")
METHODS = ("tfp", "tfi", "guided")
TABLES = ("run", "stream", "classical", "guided", "export")


# ------------------------------------------------------------------------------------ the tables


@dataclass
class RunTable(Config):
    """Which windows a reconstruction covers and by what method.

    Attributes:
        method: ``"tfp"``, ``"tfi"`` or ``"guided"``.
        at: centre tick of a single window (exclusive with ``range``).
        range: ``"A:B[:STEP]"`` in ticks: windows centred on A, A+STEP, … below B.
    """

    TABLE = "run"

    method: str = param("tfp", key="export_method", label="Reconstruction", choices=METHODS,
                        help="Reconstruction method: tfp (spike count over the window), tfi (inter-spike interval) or "
                             "guided (SpikeDiff).")
    at: int | None = None
    range: str | None = None

    def __post_init__(self) -> None:
        self.check_params()


def _stream(help: str, **kw: Any) -> Any:
    """A ``[stream]`` field (unset by default) with the help and choices its command-line flag shows."""
    return dataclasses.field(default=None, metadata={"help": help, **kw})


@dataclass
class StreamTable(Config):
    """How the capture is read (``None`` = from the sidecar, the suffix or detection).

    Each field's metadata holds its flag's help (and ``choices``/``metavar``): the CLI's geometry
    flags are generated from this table (:func:`spikeview.cli._common.add_geometry_flags`).
    """

    format: str | None = _stream("file format (default: sidecar, suffix or detection)",
                                 choices=FORMATS)
    width: int | None = _stream("frame width in pixels")
    height: int | None = _stream("frame height in pixels")
    cfa: str | None = _stream("colour filter: top-left 2x2 after the flips, or 'none' for monochrome",
                              metavar="{RGGB,BGGR,GRBG,GBRG,none}")
    flip_vertical: bool | None = _stream("rows are stored upside down (the ecosystem default for .dat files)")
    flip_horizontal: bool | None = _stream("columns are stored mirrored")
    tick_rate: float | None = _stream("readouts per second (default 20000)")
    layout: str | None = _stream("axis order of .npy/.npz arrays", choices=("thw", "hwt"))
    camera: str | None = _stream("camera profile from spikeview calibrate: its dark, flat-field and hot-pixel corrections "
                                 "apply to the rates (and --white-balance auto or profile uses its colour response)",
                                 metavar="PROFILE.toml")

    @classmethod
    def from_info(cls, info: Any, layout: str | None = None) -> StreamTable:
        from spikeview.cfa import cfa_to_str

        cam = getattr(info, "camera", None)
        return cls(info.format, info.width, info.height, cfa_to_str(info.cfa), info.flip_vertical,
                   info.flip_horizontal, info.tick_rate, layout if info.format == "npz" else None,
                   str(cam.path.absolute()) if cam is not None and cam.path is not None else None)

    def open_kwargs(self) -> dict[str, Any]:
        """Keyword arguments of :func:`spikeview.io.open_source` (unset entries left out; the camera profile is
        attached after opening: :func:`spikeview.classical.calibration.attach`)."""
        return {k: v for k, v in dataclasses.asdict(self).items() if v is not None and k != "camera"}


# ------------------------------------------------------------------------------- the view table


@dataclass(frozen=True)
class Param(ParamMeta):
    """One settable parameter as the views see it: its field's :class:`~spikeview.config.ParamMeta` with
    the recipe path and the flag and app key resolved.

    Attributes:
        path: ``table.field`` in the recipe (``guided.k``).
        flag: command-line flag (``--k``); booleans get ``--flag/--no-flag``; ``""`` = no flag.
        key: the app's control (session parameter name); ``""`` = not in the app.
        label, help, unit, lo, hi, lo_open, step, choices: as declared (:func:`~spikeview.config.param`).
    """

    path: str = ""

    @property
    def table(self) -> str:
        return self.path.split(".", 1)[0]

    @property
    def field(self) -> str:
        return self.path.split(".", 1)[1]

    @property
    def dest(self) -> str:
        """argparse destination of :attr:`flag`."""
        return self.flag.lstrip("-").replace("-", "_")

    @property
    def optional(self) -> bool:
        """Whether the field may be unset (``None``: the data or the plan decides)."""
        return _optional(self.table, self.field)

    def kind(self) -> Any:
        """The field's type (``int``, ``float``, ``bool``, ``str``; optional types unwrapped)."""
        tp = _field_types()[self.table][self.field]
        return tp

    def default(self) -> Any:
        return getattr(getattr(Recipe(), self.table), self.field)

    def check(self, value: Any, name: str | None = None) -> Any:
        """``value`` converted to the field's type; :class:`ParameterError` naming ``name`` if it does not fit.

        ``name`` is the word the person typed (``--k`` in the CLI, the control's label in the app);
        by default the dotted path.
        """
        name = name or self.path
        kind = self.kind()
        if value is None:
            if self.optional:
                return None
            raise ParameterError(f"{name} needs a value; see --help for its range.")
        return check_value(name, kind, value, self.lo, self.hi, self.choices, lo_open=self.lo_open,
                           unit=self.unit)


def _params() -> tuple[Param, ...]:
    """One :class:`Param` per field declared with :func:`~spikeview.config.param`, table by table."""
    out = []
    for table, cls in (("run", RunTable), ("classical", ClassicalConfig), ("guided", GuidedConfig), ("export", ExportConfig)):
        for name, m in param_fields(cls):
            flag = "--" + name.replace("_", "-") if m.flag is None else m.flag
            key = name if m.key is None else m.key
            out.append(Param(**{**dataclasses.asdict(m), "flag": flag, "key": key}, path=f"{table}.{name}"))
    return tuple(out)


#: every parameter a person sets, generated from the configs' fields: the CLI flags and the app's controls are views of it
PARAMS: tuple[Param, ...] = _params()

BY_PATH: dict[str, Param] = {p.path: p for p in PARAMS}

#: parameters the app has no control for, with the reason; the app reads them from a preset (File ▸ Load preset…)
#: and writes them into the presets and exports it makes, so they are not lost. The README's table says so, and a
#: test holds every other app parameter to a control of the app.
PRESET_ONLY: dict[str, str] = {
    "classical.tfi_half_window": "the TFI's interval search, a property of the method more than of a capture",
    "guided.lam": "the HQS data step's weight, tuned once on the bench (the guidance weight s is the app's knob)",
    "guided.sigma_scale": "the noise the prior is told, tuned once on the bench",
    "guided.warm_start": "acts on sequences (exports and ranges), not on the single window the app's Run samples",
    "guided.tile": "memory and speed of large frames; the plan's tiles row and the Tiles overlay show what it did",
    "export.gamma": "the γ of the Gamma display curve, whose choice is the app's Display curve control",
}
BY_KEY: dict[str, Param] = {p.key: p for p in PARAMS if p.key}
BY_FLAG: dict[str, Param] = {p.flag: p for p in PARAMS if p.flag}


def check(path: str, value: Any, name: str | None = None) -> Any:
    """Validate ``value`` for the parameter at ``path`` (see :meth:`Param.check`)."""
    return BY_PATH[path].check(value, name)


# ------------------------------------------------------------------------------------ the recipe


_TYPES: dict[str, dict[str, Any]] = {}


def _field_types() -> dict[str, dict[str, Any]]:
    if not _TYPES:
        import typing

        for name, cls in (("run", RunTable), ("stream", StreamTable), ("classical", ClassicalConfig),
                          ("guided", GuidedConfig), ("export", ExportConfig)):
            hints = typing.get_type_hints(cls)
            _TYPES[name] = {k: _base_type(v) for k, v in hints.items()}
            _TYPES[name + "?"] = {k: _is_optional(v) for k, v in hints.items()}
    return _TYPES


def _is_optional(tp: Any) -> bool:
    import types
    import typing

    return typing.get_origin(tp) in (typing.Union, types.UnionType) and type(None) in typing.get_args(tp)


def _base_type(tp: Any) -> Any:
    import types
    import typing

    if typing.get_origin(tp) in (typing.Union, types.UnionType):
        args = [a for a in typing.get_args(tp) if a is not type(None)]
        return args[0] if len(args) == 1 else tp
    return tp


def _optional(table: str, field: str) -> bool:
    return _field_types()[table + "?"][field]


@dataclass
class Recipe(Config):
    """Everything that decides a reconstruction and its output (see the module docstring)."""

    run: RunTable = dataclasses.field(default_factory=RunTable)
    stream: StreamTable = dataclasses.field(default_factory=StreamTable)
    classical: ClassicalConfig = dataclasses.field(default_factory=ClassicalConfig)
    guided: GuidedConfig = dataclasses.field(default_factory=GuidedConfig)
    export: ExportConfig = dataclasses.field(default_factory=ExportConfig)

    def __post_init__(self) -> None:
        if self.run.method in ("tfp", "tfi") and self.classical.method != self.run.method:
            self.classical = self.classical.replace(method=self.run.method)  # one home: [run] method
        c = self.classical
        changes = {g: getattr(c, k) for k, g in SHARED.items()}
        changes["use_cast"] = None if c.colour_cast else False
        if any(getattr(self.guided, k) != v for k, v in changes.items()):
            self.guided = self.guided.replace(**changes)

    # --- values by dotted path ------------------------------------------------------------
    def get(self, path: str) -> Any:
        table, field = path.split(".", 1)
        return getattr(getattr(self, table), field)

    def with_values(self, values: Mapping[str, Any], names: Mapping[str, str] | None = None) -> Recipe:
        """A copy with ``values[path]`` set (each checked by the view table; ``names[path]`` is the
        word used in an error, e.g. the flag). Classical methods' tables are rebuilt once per table."""
        by_table: dict[str, dict[str, Any]] = {}
        for path, value in values.items():
            if path not in BY_PATH and path.split(".", 1)[0] not in TABLES:
                raise ParameterError(f"unknown parameter {path!r}.")
            if path in BY_PATH:
                value = check(path, value, (names or {}).get(path))
            table, field = path.split(".", 1)
            by_table.setdefault(table, {})[field] = value
        new = {}
        for t, f in by_table.items():
            try:
                new[t] = getattr(self, t).replace(**f)
            except ParameterError as e:  # a table's own rule (e.g. guided.tile): named as the caller names it
                msg = str(e)
                for field in f:
                    path = f"{t}.{field}"
                    if names and names.get(path) and msg.startswith(path + " "):
                        raise ParameterError(names[path] + msg[len(path):]) from None
                raise
        return dataclasses.replace(self, **new)

    # --- TOML -------------------------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        d = super().to_dict()
        for k in DERIVED_GUIDED:
            d["guided"].pop(k, None)
        d["classical"].pop("method", None)
        if not d["stream"]:
            d.pop("stream")
        return d

    @classmethod
    def from_dict(cls, data: dict[str, Any], where: str | None = None) -> Recipe:
        where = where or "recipe"
        if "params" in data and isinstance(data["params"], dict) and not set(data) & {"guided", "classical"}:
            data = data["params"]  # the record an export carries
        unknown = sorted(set(data) - set(TABLES))
        if unknown:
            raise ParameterError(f"{where}: unknown table(s) {', '.join(unknown)}; a preset holds {', '.join(TABLES)}.")
        data = {k: dict(v) if isinstance(v, dict) else v for k, v in data.items()}
        guided = data.get("guided")
        if isinstance(guided, dict):
            classical = data.setdefault("classical", {})
            for ck, gk in SHARED.items():
                if gk in guided:  # an older preset: the observation fields were repeated in [guided]
                    gv = guided.pop(gk)
                    if ck not in classical:
                        classical[ck] = gv
                    elif classical[ck] != gv:
                        raise ParameterError(
                            f"{where}: [guided] {gk} = {gv!r} disagrees with [classical] {ck} = {classical[ck]!r}; "
                            f"{ck} has one home, [classical]: delete it from [guided]."
                        )
            use_cast = guided.pop("use_cast", None)
            if use_cast is False and "colour_cast" not in classical:
                classical["colour_cast"] = False
        classical = data.get("classical")
        if isinstance(classical, dict) and "method" in classical:  # older presets: the method lived here too
            method = classical.pop("method")
            run = data.setdefault("run", {})
            if isinstance(run, dict):
                run.setdefault("method", method)
        return super().from_dict(data, where=where)

    @classmethod
    def load(cls, path: Any, table: str | None = None) -> Recipe:
        data = load_toml(path)
        if not data:
            raise ParameterError(f"{path}: the preset is empty; save one from the app (File ▸ Save preset…) or use a "
                                 "<out>.preset.toml a run wrote.")
        try:
            recipe = cls.from_dict(data, where=str(path))
        except ParameterError as e:  # a value a config rejects: the sentence names the file too
            text = str(e)
            raise ParameterError(text if text.startswith(str(path)) else f"{path}: {text}") from None
        tables = data["params"] if "params" in data and isinstance(data["params"], dict) and not set(data) & set(TABLES) else data
        if not {"classical", "guided", "export"} & set(tables):
            raise InputFileError(f"{path}: no [classical], [guided] or [export] table; it is not a spikeview preset.")
        return recipe

    def save(self, path: Any, header: str = "# spikeview recipe (read by the app and by `spikeview reconstruct --preset`)") -> Any:
        from spikeview._files import write_atomic

        return write_atomic(path, header + "\n" + self.to_toml(), "the preset", "choose a folder you can write to")

    # --- what a run needs --------------------------------------------------------------------
    @property
    def method(self) -> str:
        return self.run.method

    def span(self) -> int:
        """Ticks one output window covers (TFI: twice its half-window)."""
        return 2 * self.classical.tfi_half_window if self.run.method == "tfi" else self.classical.window


# ----------------------------------------------------------------------------------- the help


def help_rows() -> list[tuple[str, str, str, str]]:
    """``(path, flag, app control, one sentence with the unit and default)`` for every parameter."""
    defaults = Recipe()
    rows = []
    for p in PARAMS:
        d = getattr(getattr(defaults, p.table), p.field)
        shown = "the plan decides" if d is None and p.kind() is bool else ("unset" if d is None else (
            ("on" if d else "off") if isinstance(d, bool) else f"{d:.4g}" if isinstance(d, float) else str(d)))
        unit = f" {p.unit}" if p.unit and d is not None and not isinstance(d, str) and p.unit != "of full scale" else ""
        label = f"— (preset only: {PRESET_ONLY[p.path]})" if p.path in PRESET_ONLY else (p.label if p.key else "—")
        rows.append((p.path, p.flag or "—", label, f"{p.help} Default: {shown}{unit}."))
    return rows


def markdown_table() -> str:
    """The README's parameter table (kept equal to :data:`PARAMS` by a test)."""
    lines = ["| recipe path | flag | app control | meaning |", "|---|---|---|---|"]
    for path, flag, label, text in help_rows():
        lines.append(f"| `{path}` | `{flag}` | {label} | {text} |")
    return "\n".join(lines)


# ------------------------------------------------------------------------------------- the CLI


def add_flags(parser: Any, tables: Iterable[str] = ("classical", "guided", "export"), *, skip: Iterable[str] = ()) -> None:
    """Add one flag per :data:`PARAMS` row of ``tables`` (grouped by table), defaults shown from the recipe."""
    import argparse

    titles = {"run": "run", "classical": "observation and classical reconstruction ([classical])",
              "guided": "guided reconstruction, --method guided ([guided])", "export": "output ([export])"}
    skip = set(skip)
    defaults = Recipe()
    for table in tables:
        g = parser.add_argument_group(titles[table])
        for p in PARAMS:
            if p.table != table or not p.flag or p.flag in skip:
                continue
            default = getattr(getattr(defaults, table), p.field)
            shown = "the plan decides" if default is None and p.field == "quantise" else (
                "unset" if default is None else (f"{default:.4g}" if isinstance(default, float) else str(default)))
            text = f"{p.help} (default: {shown})".replace("%", "%%")
            kind = p.kind()
            if kind is bool:
                g.add_argument(p.flag, dest=p.dest, action=argparse.BooleanOptionalAction, default=None, help=text)
            elif p.choices:  # lower-case choices take any case (--method TFP, as --cfa rggb)
                lower = all(isinstance(c, str) and c == c.lower() for c in p.choices)
                g.add_argument(p.flag, dest=p.dest, choices=list(p.choices), default=None, help=text,
                               type=str.lower if lower else str)
            else:
                g.add_argument(p.flag, dest=p.dest, type=kind if kind in (int, float) else str, default=None,
                               metavar=p.unit.split()[0].upper() if p.unit and " " not in p.unit else None, help=text)


def given_flags(args: Any) -> dict[str, Any]:
    """``{path: value}`` for every :data:`PARAMS` flag given on the command line."""
    out = {}
    for p in PARAMS:
        if p.flag and getattr(args, p.dest, None) is not None:
            out[p.path] = getattr(args, p.dest)
    return out


def apply_flags(recipe: Recipe, args: Any) -> Recipe:
    """``recipe`` with the flags the user gave; errors name the flag."""
    values = given_flags(args)
    if "guided.model_path" in values and values["guided.model_path"] == "":
        values["guided.model_path"] = None
    return recipe.with_values(values, names={p: BY_PATH[p].flag for p in values})
