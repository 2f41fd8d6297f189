"""Parameter presets: the session's parameters as the TOML tables the core configs read (no Qt).

A preset file holds one table per core config, with that config's field names, so the same file
drives the app and the command line and every value is validated by the config that owns it::

    [classical]          # spikeview.classical.ClassicalConfig
    method = "tfp"
    window = 10
    demosaic = "bilinear"
    colour_cast = true
    eta = 2.0
    tfi_half_window = 32

    [guided]             # spikeview.guided.GuidedConfig
    guidance = "hqs"
    steps = 8
    ...

    [export]             # spikeview.export.ExportConfig
    fps = 30.0
    ...

    [app]                # display and playback settings only the app uses
    transfer = "srgb"
    ...

Exported files record the same dict as their ``params`` (see :func:`spikeview.export.read_export_metadata`),
so a preset can also be loaded from an export's record (a TOML with a ``[params]`` table).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from spikeview.config import load_toml
from spikeview.errors import InputFileError, ParameterError
from spikeview.gui.model import SPECS, Session

#: session parameter → ClassicalConfig field (same name unless given)
_CLASSICAL = ("window", "tfi_half_window", "demosaic", "colour_cast", "eta")
#: session parameter → GuidedConfig field
_GUIDED = {"guidance": "guidance", "prior": "prior", "model_path": "model_path", "steps": "steps", "t_start": "t_start",
           "s": "s", "k": "k", "levels": "levels", "eta": "eta", "window": "window", "seed": "seed"}
#: session parameter → ExportConfig field
_EXPORT = {"export_fps": "fps", "black": "black", "white": "white", "transfer": "transfer", "gamma": "gamma"}
#: only the app uses these
_APP = ("black", "white", "transfer", "gamma", "show_pyramid", "speed", "slowmo", "loop", "export_format",
        "export_range", "export_method")


def preset_dict(session: Session | dict[str, Any]) -> dict[str, Any]:
    """The session's parameters as a dict of config tables (validated by each config)."""
    from spikeview.classical.reconstruct import ClassicalConfig
    from spikeview.export import ExportConfig
    from spikeview.gui.jobs import guided_config

    p = session.params if isinstance(session, Session) else session
    classical = ClassicalConfig(method=p["export_method"] if p["export_method"] in ("tfp", "tfi") else "tfp",
                                **{k: p[k] for k in _CLASSICAL})
    guided = guided_config(p)
    export = ExportConfig(**{v: p[k] for k, v in _EXPORT.items() if k != "white"},
                          white=max(float(p["white"]), float(p["black"]) + 1e-3))
    g = guided.to_dict()
    g.pop("diffusion", None)  # the app always samples; the CLI's default ("auto") applies elsewhere
    return {"classical": classical.to_dict(), "guided": g, "export": export.to_dict(),
            "app": {k: p[k] for k in _APP}}


def save_preset(session: Session, path: str | os.PathLike[str]) -> Path:
    """Write the session's parameters to ``path`` as TOML (atomically)."""
    import tomli_w

    path = Path(path)
    text = "# spikeview parameter preset (read by the app and by `spikeview reconstruct --preset`)\n"
    text += tomli_w.dumps(preset_dict(session))
    tmp = path.with_name(f".{path.name}.tmp{os.getpid()}")
    try:
        tmp.write_text(text, encoding="utf-8")
        os.replace(tmp, path)
    except OSError as e:
        tmp.unlink(missing_ok=True)
        from spikeview.errors import OutputFileError

        raise OutputFileError(f"{path}: cannot write the preset ({e.strerror}); choose a folder you can write to.") from None
    return path


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
    known = {"classical", "guided", "export", "app"}
    if not known & set(data):
        raise InputFileError(f"{where}: no [classical], [guided], [export] or [app] table; it is not a spikeview preset.")
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
    app = data.get("app", {})
    if not isinstance(app, dict):
        raise ParameterError(f"{where}: [app] must be a table.")
    unknown = sorted(set(app) - set(_APP))
    if unknown:
        raise ParameterError(f"{where} [app]: unknown setting(s) {', '.join(unknown)}; valid ones are {', '.join(_APP)}.")
    out.update(app)
    for k, v in out.items():  # the app's own ranges (narrower for sliders) must hold too
        out[k] = SPECS[k].validate(v)
    return out


def load_preset(session: Session, path: str | os.PathLike[str]) -> None:
    """Load a preset into the session as one undo step (nothing changes if any value is invalid)."""
    values = params_from_preset(load_toml(path), where=str(path))
    session.update_params(values, label=f"Load preset {Path(path).name}")
