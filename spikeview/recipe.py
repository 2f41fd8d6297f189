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

**One table of views.** :data:`PARAMS` lists every parameter a person can set, by dotted path
(``guided.k``), with its command-line flag (``--k``), its app control (the session key ``k``), label,
unit, range and one-sentence help. The CLI's flags (:func:`add_flags`, :func:`apply_flags`), the
app's controls (:mod:`spikeview.gui.model`) and the configs' range checks are all generated from
it; nothing else translates names.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

from spikeview.classical_config import ClassicalConfig
from spikeview.config import Config, load_toml
from spikeview.errors import InputFileError, ParameterError
from spikeview.export.settings import EXR_COMPRESSIONS, TRANSFERS, X264_PRESETS, ExportConfig
from spikeview.guided.config import PRECISIONS, GuidedConfig

#: ``[classical]`` field → the ``GuidedConfig`` field it sets (the observation both methods share)
SHARED: dict[str, str] = {"window": "window", "demosaic": "demosaic", "eta": "eta", "alpha": "alpha",
                          "alpha_max_windows": "alpha_max_windows"}
#: ``GuidedConfig`` fields derived from ``[classical]`` (never written in ``[guided]``)
DERIVED_GUIDED = tuple(SHARED.values()) + ("use_cast",)
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

    method: str = "tfp"
    at: int | None = None
    range: str | None = None

    def __post_init__(self) -> None:
        check("run.method", self.method)


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
                                 choices=("plain", "raw400", "raw1m", "npz"))
    width: int | None = _stream("frame width in pixels")
    height: int | None = _stream("frame height in pixels")
    cfa: str | None = _stream("colour filter: top-left 2x2 after the flips, or 'none' for monochrome",
                              metavar="{RGGB,BGGR,GRBG,GBRG,none}")
    flip_vertical: bool | None = _stream("rows are stored upside down (the ecosystem default for .dat files)")
    flip_horizontal: bool | None = _stream("columns are stored mirrored")
    tick_rate: float | None = _stream("readouts per second (default 20000)")
    layout: str | None = _stream("axis order of .npy/.npz arrays", choices=("thw", "hwt"))

    @classmethod
    def from_info(cls, info: Any, layout: str | None = None) -> StreamTable:
        from spikeview.cfa import cfa_to_str

        return cls(info.format, info.width, info.height, cfa_to_str(info.cfa), info.flip_vertical,
                   info.flip_horizontal, info.tick_rate, layout if info.format == "npz" else None)

    def open_kwargs(self) -> dict[str, Any]:
        """Keyword arguments of :func:`spikeview.io.open_source` (unset entries left out)."""
        return {k: v for k, v in dataclasses.asdict(self).items() if v is not None}


# ------------------------------------------------------------------------------- the view table


@dataclass(frozen=True)
class Param:
    """One settable parameter: where it lives, how the CLI and the app show it, what it accepts.

    Attributes:
        path: ``table.field`` in the recipe (``guided.k``).
        flag: command-line flag (``--k``); booleans get ``--flag/--no-flag``; ``""`` = no flag.
        key: the app's control (session parameter name); ``""`` = not in the app.
        label: the control's label and the name used in the app's messages.
        help: one sentence, with the unit.
        unit: unit shown beside numbers (``ticks``, ``/255``…).
        lo, hi: accepted range (``None`` = unbounded); ``lo_open`` excludes ``lo``.
        step: slider/spin step in the app.
        choices: accepted strings.
    """

    path: str
    flag: str
    key: str
    label: str
    help: str
    unit: str = ""
    lo: float | None = None
    hi: float | None = None
    lo_open: bool = False
    step: float | None = None
    choices: tuple[str, ...] = ()

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


def _p(path: str, flag: str, key: str, label: str, help: str, **kw: Any) -> Param:
    return Param(path, flag, key, label, help, **kw)


_S255 = 75.0 / 255.0
#: every parameter a person sets: the CLI flags and the app's controls are generated from this table
PARAMS: tuple[Param, ...] = (
    # --- run
    _p("run.method", "--method", "export_method", "Reconstruction",
       "Reconstruction method: tfp (spike count over the window), tfi (inter-spike interval) or guided (SpikeDiff).",
       choices=METHODS),
    # --- observation (shared by the classical methods and the guided sampler)
    _p("classical.window", "--window", "window", "Window Δτ",
       "TFP window Δτ in ticks (10 ticks = 0.5 ms at 20 kHz); also the guided sampler's observation.",
       unit="ticks", lo=1, hi=4096, step=1),
    _p("classical.tfi_half_window", "--tfi-half-window", "tfi_half_window", "TFI half-window",
       "TFI searches this many ticks before and after the centre tick.", unit="ticks", lo=1, hi=512, step=1),
    _p("classical.demosaic", "--demosaic", "demosaic", "Demosaicking",
       "Demosaicking of TFP/TFI outputs and of the guided start estimate: auto (the plan picks from the measured noise: bilinear where noise dominates, malvar2004 where clean or denoised afterwards), bilinear, malvar2004 or menon2007.",
       choices=("auto", "bilinear", "malvar2004", "menon2007")),
    _p("classical.colour_cast", "--colour-cast", "colour_cast", "Correct colour cast",
       "Undo the sensor's per-channel response with gray-world gains estimated once per sequence (Bayer streams)."),
    _p("classical.eta", "--eta", "eta", "Colour range η",
       "Range parameter η of the colour cast: after correction each channel's sequence mean is 1/η (2 → 0.5).",
       lo=0.0, lo_open=True, hi=8.0, step=0.05),
    # --- guided sampler
    _p("guided.guidance", "--guidance", "guidance", "Guidance rule",
       "How the data steers each step: hqs (a data step on the clean estimate, fast) or dps (gradient through the prior).",
       choices=("hqs", "dps")),
    _p("guided.prior", "--prior", "prior", "Prior",
       "Natural-image prior: ffdnet (embedded) or sd (a local Stable Diffusion 2.x model, optional extra).",
       choices=("ffdnet", "sd")),
    _p("guided.model_path", "--model", "model_path", "Model weights",
       "Weights folder for --prior sd (or an FFDNet .pth replacing the packaged weights); empty = packaged FFDNet."),
    _p("guided.steps", "--steps", "steps", "Steps", "Number of sampler steps (prior calls) per window.",
       lo=1, hi=1000, step=1),
    _p("guided.t_start", "--t-start", "t_start", "Start noise t_s",
       "Start noise level t_s as a fraction of full scale (0.196 = 50/255; FFDNet is trained up to 75/255 = 0.294).",
       unit="of full scale", lo=0.0, hi=_S255, step=1.0 / 255.0),
    _p("guided.s", "--s", "s", "Guidance weight s",
       "Weight of the data against the prior: the DPS step size, or under HQS the fraction of the data step taken (1 = full, 0 = none).",
       lo=0.0, hi=10.0, step=0.05),
    _p("guided.lam", "--lam", "lam", "HQS λ",
       "HQS prior weight λ in ρ_t = λσ_n²/σ_t² (larger trusts the prior more).", lo=0.0, lo_open=True, hi=100.0, step=0.1),
    _p("guided.quantise", "--quantise", "quantise", "Soft quantisation Q",
       "Model the TFP's quantisation to multiples of 1/Δτ in the forward model (unset: the plan decides)."),
    _p("guided.k", "--k", "k", "Quantiser sharpness k",
       "Sharpness k of the soft quantiser Q (the paper's best: 50); acts only when Q is on.", lo=0.0, hi=1000.0, step=1.0),
    _p("guided.levels", "--levels", "levels", "Pyramid levels L",
       "Band-pass levels L of the multiscale Laplacian loss (0 = plain residual; capped by the frame size).",
       lo=0, hi=6, step=1),
    _p("guided.sigma_scale", "--sigma-scale", "sigma_scale", "Prior noise scale",
       "Factor on the data-derived noise level handed to the prior (1 = as measured).", lo=0.0, lo_open=True, hi=10.0, step=0.05),
    _p("guided.seed", "--seed", "seed", "Seed", "Random seed (same seed and machine: same result).", lo=0, hi=2**31 - 1, step=1),
    _p("guided.precision", "--precision", "precision", "Prior precision",
       "Arithmetic of the FFDNet prior: auto (the fastest path within 0.1 dB / 0.005 SSIM of float32 on the bench, from the CPU's features), float32 (the reference pixels), float32-fast (NNPACK's fast float32 convolution) or bfloat16-mixed (bfloat16 on high-noise steps).",
       choices=PRECISIONS),
    _p("guided.warm_start", "--warm-start", "warm_start", "Warm start",
       "Start each window of a sequence from the previous result re-noised to t_s (faster, may smear motion)."),
    _p("guided.temporal_radius", "--temporal-radius", "temporal_radius", "Temporal radius",
       "Neighbouring windows on each side whose spikes a guided frame may borrow, aligned and used only where they match (0 = the window alone).",
       unit="windows", lo=0, hi=8, step=1),
    # --- export
    _p("export.fps", "--fps", "export_fps", "Output fps", "MP4 playback rate in frames per second.",
       unit="fps", lo=0.01, hi=1000.0, step=1.0),
    _p("export.compression", "--compression", "", "EXR compression", "EXR compression (all lossless).",
       choices=EXR_COMPRESSIONS),
    _p("export.crf", "--crf", "", "MP4 quality", "libx264 constant rate factor, 0 (best) to 51; 18 is visually lossless.",
       lo=0, hi=51),
    _p("export.preset", "--x264-preset", "", "x264 preset", "libx264 speed/size preset.", choices=X264_PRESETS),
    _p("export.black", "--black", "black", "Black level",
       "Linear value shown as black in PNG/MP4 and the app (fixed, never per frame).", lo=0.0, hi=1.0, step=0.01),
    _p("export.white", "--white", "white", "White point",
       "Exposure: the linear value (Y·α/η units) that becomes 1.0 in EXR and full scale in npy/PNG/MP4 and the app; "
       "unset, the sequence's 99.9th percentile, chosen once and printed.", lo=0.0, lo_open=True, hi=16.0, step=0.01),
    _p("export.transfer", "--transfer", "transfer", "Display curve",
       "Display encoding of PNG/MP4 and the app: srgb, gamma (power 1/gamma) or linear.", choices=TRANSFERS),
    _p("export.gamma", "--gamma", "gamma", "Gamma", "Exponent of the gamma display curve.", lo=0.2, hi=5.0, step=0.05),
)

BY_PATH: dict[str, Param] = {p.path: p for p in PARAMS}
BY_KEY: dict[str, Param] = {p.key: p for p in PARAMS if p.key}
BY_FLAG: dict[str, Param] = {p.flag: p for p in PARAMS if p.flag}


def check(path: str, value: Any, name: str | None = None) -> Any:
    """Validate ``value`` for the parameter at ``path`` (see :meth:`Param.check`)."""
    return BY_PATH[path].check(value, name)


def check_table(table: str, cfg: Any) -> None:
    """Range-check every field of ``cfg`` that :data:`PARAMS` lists under ``table`` (config ``__post_init__``)."""
    for p in PARAMS:
        if p.table == table:
            check(p.path, getattr(cfg, p.field))


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
        new = {t: getattr(self, t).replace(**f) for t, f in by_table.items()}
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
        rows.append((p.path, p.flag or "—", p.label if p.key else "—", f"{p.help} Default: {shown}{unit}."))
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
            elif p.choices:
                g.add_argument(p.flag, dest=p.dest, choices=list(p.choices), default=None, help=text)
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
