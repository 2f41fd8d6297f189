"""Sidecars: the TOML file beside every spike file spikeview writes (``scene.dat`` → ``scene.dat.toml``).

A plain ``.dat`` file has no header, so its geometry, orientation and colour filter live here::

    [stream]
    format = "plain"          # plain | raw400 | raw1m | npz
    width = 1000
    height = 1000
    cfa = "BGGR"              # top-left 2x2 *after* the flips, or "none"
    flip_vertical = true
    flip_horizontal = false
    tick_rate = 20000.0       # readouts per second

    [simulation]              # optional free-form tables, e.g. the simulator's settings
    ...
    [recording]               # or the live recorder's drop counters
    ...

:func:`~spikeview.io.open.open_source` reads the sidecar automatically; arguments given to it
override the sidecar's values.
"""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path
from typing import Any

from spikeview._files import SIDECAR_SUFFIX, sidecar_path  # noqa: F401  (their home: the file rules)
from spikeview.cfa import cfa_to_str, parse_cfa
from spikeview.config import Config, load_toml
from spikeview.errors import InputFileError, ParameterError, SpikeviewError
from spikeview.io.source import DEFAULT_TICK_RATE, FORMATS, StreamInfo, check_tick_rate


@dataclasses.dataclass
class StreamSettings(Config):
    """The ``[stream]`` table of a sidecar.

    Attributes:
        format: one of ``plain``, ``raw400``, ``raw1m``, ``npz`` (``npz`` also covers ``.npy``).
        width, height: decoded frame size in pixels.
        cfa: top-left 2×2 of the decoded frame after the flips (``"RGGB"`` …) or ``"none"``.
        flip_vertical, flip_horizontal: flips applied after decoding.
        tick_rate: readouts per second (Hz).

    How the rates map to display is a table of its own, ``[display] transfer = "srgb" | "linear" | "gamma"``
    (:func:`spikeview.transfer.source_transfer`; older readers ignore a table they do not know).
    """

    format: str
    width: int
    height: int
    cfa: str = "none"
    flip_vertical: bool = False
    flip_horizontal: bool = False
    tick_rate: float = DEFAULT_TICK_RATE

    def __post_init__(self) -> None:
        if self.format not in FORMATS:
            raise ParameterError(f"format {self.format!r} is unknown: use one of {', '.join(FORMATS)}.")
        if self.width < 1 or self.height < 1:
            raise ParameterError(f"width and height must be positive, got {self.width}x{self.height}.")
        self.tick_rate = check_tick_rate(self.tick_rate)
        self.cfa = cfa_to_str(parse_cfa(self.cfa))

    @classmethod
    def from_info(cls, info: StreamInfo) -> StreamSettings:
        """The settings that reproduce ``info`` when the file is opened again."""
        return cls(format=info.format, width=int(info.width), height=int(info.height), cfa=cfa_to_str(info.cfa),
                   flip_vertical=bool(info.flip_vertical), flip_horizontal=bool(info.flip_horizontal),
                   tick_rate=float(info.tick_rate))


@dataclasses.dataclass
class Sidecar:
    """A parsed sidecar: ``stream`` (``None`` when the file has no ``[stream]`` table) and the other tables."""

    path: Path
    stream: StreamSettings | None
    tables: dict[str, Any]


def is_sidecar(path: str | os.PathLike[str]) -> bool:
    """``path`` is a sidecar (settings of the spike file beside it: ``scene.dat.toml`` next to ``scene.dat``), not a
    preset or another TOML file: the one rule of the app's Open and :func:`spikeview.io.open.open_source`."""
    path = Path(path)
    return path.suffix == SIDECAR_SUFFIX and path.with_suffix("").is_file()


def read_sidecar(path: str | os.PathLike[str]) -> Sidecar | None:
    """Read the sidecar of spike file ``path``; ``None`` when there is none.

    Raises:
        InputFileError: the sidecar exists but is not valid TOML, or its ``[stream]`` table has
            unknown keys or wrong values (the message names the sidecar).
    """
    side = sidecar_path(path)
    if not side.is_file():
        return None
    data = load_toml(side)
    stream_data = data.pop("stream", None)
    stream = None
    if stream_data is not None:
        if not isinstance(stream_data, dict):
            raise InputFileError(f"{side}: [stream] must be a table; fix or delete the sidecar.")
        required = [f.name for f in dataclasses.fields(StreamSettings)
                    if f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING]
        missing = [k for k in required if k not in stream_data]
        if missing:
            example = {"format": 'format = "plain"', "width": "width = 1000", "height": "height = 1000"}
            raise InputFileError(f"{side}: the [stream] table has no {' and no '.join(missing)}; add "
                                 f"{', '.join(example.get(k, k) for k in missing)} (the real values) to it, or delete "
                                 "the sidecar and pass --width and --height.")
        try:
            stream = StreamSettings.from_dict(stream_data, where=f"{side} [stream]")
        except SpikeviewError as e:
            raise InputFileError(f"{side}: {_strip_where(str(e), side)} Fix or delete the sidecar.") from None
    display = data.get("display")
    if display is not None:
        from spikeview.transfer import TRANSFERS

        shown = display.get("transfer") if isinstance(display, dict) else None
        if not isinstance(display, dict) or ("transfer" in display and shown not in TRANSFERS):
            raise InputFileError(f"{side}: [display] transfer = {shown!r} is not a display curve; use one of "
                                 f"{', '.join(repr(t) for t in TRANSFERS)}, or delete the line.")
    return Sidecar(path=side, stream=stream, tables=data)


def _strip_where(msg: str, side: Path) -> str:
    return msg.removeprefix(f"{side}: ")


def write_sidecar(path: str | os.PathLike[str], info: StreamInfo | StreamSettings,
                  extra_tables: dict[str, dict[str, Any]] | None = None) -> Path:
    """Write the sidecar of spike file ``path`` atomically (temporary file, then rename).

    Args:
        path: the spike file (the sidecar goes to ``<path>.toml``).
        info: the stream's :class:`StreamInfo` (its format, geometry, CFA, flips, tick rate) or
            ready :class:`StreamSettings`.
        extra_tables: optional free-form tables, e.g. ``{"simulation": {...}, "recording": {...}}``;
            values must be TOML-representable (``None`` values are left out).

    Returns:
        The sidecar's path.
    """
    import tomli_w

    from spikeview.transfer import DISPLAY_KEY

    settings = info if isinstance(info, StreamSettings) else StreamSettings.from_info(info)
    doc: dict[str, Any] = {"stream": settings.to_dict()}
    display = None if isinstance(info, StreamSettings) else (info.extra or {}).get(DISPLAY_KEY)
    if display is not None and "display" not in (extra_tables or {}):
        doc["display"] = {"transfer": display}  # how the rates map to display (spikeview.transfer.source_transfer)
    for name, table in (extra_tables or {}).items():
        if name == "stream":
            raise ParameterError("extra_tables cannot contain a [stream] table; it is written from the stream info.")
        doc[name] = _toml_ready(table)
    side = sidecar_path(path)
    try:
        text = tomli_w.dumps(doc)
    except TypeError as e:
        raise ParameterError(f"a sidecar table holds a value TOML cannot store ({e}); use numbers, strings, lists or tables.") from None
    from spikeview._files import write_atomic

    return write_atomic(side, text, "the sidecar")


def _toml_ready(value: Any) -> Any:
    """Drop ``None`` values and turn numpy scalars/arrays and paths into plain TOML values."""
    if isinstance(value, dict):
        return {str(k): _toml_ready(v) for k, v in value.items() if v is not None}
    if isinstance(value, (list, tuple)):
        return [_toml_ready(v) for v in value]
    if isinstance(value, Path):
        return str(value)
    if hasattr(value, "tolist") and not isinstance(value, (str, bytes)):  # numpy scalar or array
        return _toml_ready(value.tolist())
    return value
