"""Parameter presets: the session's parameters as the TOML file ``spikeview reconstruct --preset`` reads.

A preset holds one table per core config, with that config's field names, so the same file drives
the app and the command line and every value is validated by the config that owns it — the format
the CLI writes beside its outputs (``<out>.preset.toml``, :mod:`spikeview.cli.reconstruct`)::

    [run]                # spikeview.cli.reconstruct.RunConfig: method, at / range (ticks)
    method = "tfp"
    at = 640

    [stream]             # how the capture is read (format, size, CFA, flips, tick rate)
    ...

    [classical]          # spikeview.classical.ClassicalConfig
    window = 10
    ...

    [guided]             # spikeview.guided.GuidedConfig
    ...

    [export]             # spikeview.export.ExportConfig (display levels and curve included)
    ...

Settings only the app has (playback speed, loop, per-level residual view, the export format, which
the CLI takes from the output's suffix) are remembered in the app's settings, not in presets.
Loading a preset changes parameters only: its ``[stream]`` and ``[run]`` ticks are not applied to
the open capture (File ▸ Stream settings… changes the CFA and flip).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from spikeview.config import load_toml
from spikeview.errors import InputFileError, ParameterError
from spikeview.gui.model import SPECS, Session

#: session parameters that are ClassicalConfig fields of the same name
_CLASSICAL = ("window", "tfi_half_window", "demosaic", "colour_cast", "eta")
#: session parameter → GuidedConfig field
_GUIDED = {"guidance": "guidance", "prior": "prior", "model_path": "model_path", "steps": "steps", "t_start": "t_start",
           "s": "s", "k": "k", "levels": "levels", "eta": "eta", "window": "window", "seed": "seed"}
#: session parameter → ExportConfig field
_EXPORT = {"export_fps": "fps", "black": "black", "white": "white", "transfer": "transfer", "gamma": "gamma"}
#: the tables of a preset (as the CLI's ``--preset`` accepts them)
TABLES = ("run", "stream", "classical", "guided", "export")


def preset_dict(session: Session) -> dict[str, Any]:
    """The session's parameters (and open stream, current tick or marked range) as preset tables."""
    from spikeview.cfa import cfa_to_str
    from spikeview.classical.reconstruct import ClassicalConfig
    from spikeview.export import ExportConfig
    from spikeview.gui.jobs import guided_config

    p = session.params
    method = p["export_method"]
    classical = ClassicalConfig(method=method if method in ("tfp", "tfi") else "tfp", **{k: p[k] for k in _CLASSICAL})
    guided = guided_config(p).to_dict()
    guided.pop("diffusion", None)  # the app always samples; a CLI run keeps its default
    export = ExportConfig(**{v: p[k] for k, v in _EXPORT.items() if k != "white"},
                          white=max(float(p["white"]), float(p["black"]) + 1e-3))
    out: dict[str, Any] = {"run": {"method": method}}
    src = session.source
    if src is not None:
        if p["export_range"] == "marked":
            lo, hi = session.marked_range()
            out["run"]["range"] = f"{lo}:{hi + 1}:{int(p['window'])}"
        else:
            out["run"]["at"] = int(session.tick)
        info = src.info
        if info.format in ("plain", "raw400", "raw1m", "npz"):
            out["stream"] = {"format": info.format, "width": info.width, "height": info.height, "cfa": cfa_to_str(info.cfa),
                             "flip_vertical": info.flip_vertical, "flip_horizontal": info.flip_horizontal,
                             "tick_rate": info.tick_rate}
    out.update(classical=classical.to_dict(), guided=guided, export=export.to_dict())
    return out


def save_preset(session: Session, path: str | os.PathLike[str]) -> Path:
    """Write the session's parameters to ``path`` as TOML (atomically)."""
    import tomli_w

    path = Path(path)
    text = "# spikeview parameter preset (read by the app and by `spikeview reconstruct --preset`)\n"
    text += tomli_w.dumps(preset_dict(session))
    from spikeview._files import write_atomic

    return write_atomic(path, text, "the preset", "choose a folder you can write to")


def params_from_preset(data: dict[str, Any], where: str = "preset") -> dict[str, Any]:
    """Session parameters from a preset dict; every table is validated by its config first.

    Raises:
        ParameterError: a value a config or the app rejects; the message starts with ``where``.
    """
    try:
        return _params_from_preset(data, where)
    except ParameterError as e:
        text = str(e)
        raise ParameterError(text if text.startswith(where) else f"{where}: {text}") from None


def _params_from_preset(data: dict[str, Any], where: str) -> dict[str, Any]:
    from spikeview.classical.reconstruct import ClassicalConfig
    from spikeview.export import ExportConfig
    from spikeview.guided.config import GuidedConfig

    if "params" in data and isinstance(data["params"], dict):  # an export's record
        data = data["params"]
    unknown = sorted(set(data) - set(TABLES))
    if unknown:
        raise ParameterError(f"{where}: unknown table(s) {', '.join(unknown)}; a preset holds {', '.join(TABLES)}.")
    if not {"classical", "guided", "export"} & set(data):
        raise InputFileError(f"{where}: no [classical], [guided] or [export] table; it is not a spikeview preset.")
    out: dict[str, Any] = {}
    if "guided" in data:
        g = GuidedConfig.from_dict(dict(data["guided"]), where=f"{where} [guided]")
        for k, f in _GUIDED.items():
            v = getattr(g, f)
            out[k] = "" if v is None else v
    if "classical" in data:
        c = ClassicalConfig.from_dict(dict(data["classical"]), where=f"{where} [classical]")
        out.update({k: getattr(c, k) for k in _CLASSICAL})
        out["export_method"] = c.method
    if "export" in data:
        e = ExportConfig.from_dict(dict(data["export"]), where=f"{where} [export]")
        out.update({k: getattr(e, f) for k, f in _EXPORT.items()})
    method = data.get("run", {}).get("method") if isinstance(data.get("run"), dict) else None
    if method is not None:
        out["export_method"] = method
    for k, v in out.items():  # the app's own ranges (narrower, for sliders) must hold too
        out[k] = SPECS[k].validate(v)
    return out


def load_preset(session: Session, path: str | os.PathLike[str]) -> None:
    """Load a preset into the session as one undo step (nothing changes if any value is invalid)."""
    values = params_from_preset(load_toml(path), where=str(path))
    session.update_params(values, label=f"Load preset {Path(path).name}")
