"""``spikeview reconstruct``: spikes → frames → export, with a reproducible preset.

Every run writes its full parameter set as TOML beside the outputs (``<out>.preset.toml``);
``--preset FILE`` loads such a file, and flags given explicitly on the command line override it.
"""

from __future__ import annotations

import argparse
import dataclasses
import re
import sys
from pathlib import Path
from typing import Any

from spikeview.config import Config, load_toml
from spikeview.errors import ParameterError

_PATTERN = re.compile(r"[_.\-]?%0?\d*d")


@dataclasses.dataclass
class RunConfig(Config):
    """Which windows a reconstruction covers and by what method.

    Attributes:
        method: ``"tfp"``, ``"tfi"`` or ``"guided"``.
        at: centre tick of a single window (exclusive with ``range``).
        range: ``"A:B[:STEP]"`` in ticks: windows centred on A, A+STEP, … below B.
    """

    method: str = "tfp"
    at: int | None = None
    range: str | None = None


def preset_path(out: Path) -> Path:
    """``clip.mp4`` → ``clip.mp4.preset.toml``; ``frames/f_%04d.exr`` → ``frames/f.exr.preset.toml``."""
    return out.with_name(_PATTERN.sub("", out.name) + ".preset.toml")


def _centres(run_cfg: RunConfig, n_frames: int, window: int) -> tuple[list[int], int]:
    from spikeview.cli.commands import parse_range

    if run_cfg.at is not None:
        if not 0 <= run_cfg.at < n_frames:
            raise ParameterError(f"--at {run_cfg.at} is outside the stream, which holds ticks [0, {n_frames}).")
        return [run_cfg.at], window
    if run_cfg.range is not None:
        a, b, step = parse_range(run_cfg.range, default_step=window)
        if a < 0 or a >= n_frames:
            raise ParameterError(f"--range {run_cfg.range}: start {a} is outside the stream, which holds ticks [0, {n_frames}).")
        b = min(b, n_frames)
        return list(range(a, b, step)), step
    return [n_frames // 2], window


def _load_preset(path: str | None) -> dict[str, Any]:
    if path is None:
        return {}
    data = load_toml(path)
    known = {"run", "stream", "classical", "guided", "export"}
    unknown = sorted(set(data) - known)
    if unknown:
        raise ParameterError(f"{path}: unknown table(s) {', '.join(unknown)}; a preset holds {', '.join(sorted(known))}.")
    return data


def run(args: argparse.Namespace) -> int:
    from spikeview.classical.reconstruct import ClassicalConfig, reconstruct_frames, resolve_alpha
    from spikeview.cli.commands import progress
    from spikeview.cli.main import _open_from_args
    from spikeview.export import ExportConfig, ExportMetadata, describe_slow_motion, open_exporter, slow_motion_factor

    preset = _load_preset(args.preset)
    # stream geometry: the preset's [stream] fills flags that were not given
    for key, value in preset.get("stream", {}).items():
        if getattr(args, key, None) is None and key in ("format", "width", "height", "cfa", "flip_vertical",
                                                          "flip_horizontal", "tick_rate", "layout"):
            setattr(args, key, value)

    run_cfg = RunConfig.from_dict(preset.get("run", {}), where=f"{args.preset} [run]") if preset else RunConfig()
    argv_given = set(getattr(args, "_given", ()))
    if not preset or "method" in argv_given:
        run_cfg.method = args.method
    if args.at is not None or args.range is not None:
        run_cfg.at, run_cfg.range = args.at, args.range

    out = Path(args.out)
    src = _open_from_args(args)
    for note in src.info.warnings:  # wrong geometry, truncated file ...: say so before the work
        print(f"spikeview: warning: {note}", file=sys.stderr)
    with src:
        if run_cfg.method == "guided":
            from spikeview.cli.guided import reconstruct_guided

            return reconstruct_guided(args, src, run_cfg, preset, out)

        cdict = dict(preset.get("classical", {}))
        cdict["method"] = run_cfg.method
        if "demosaic" not in cdict and args.demosaic is None:
            cdict["demosaic"] = "malvar2004"
        for flag, key in (("window", "window"), ("demosaic", "demosaic"), ("eta", "eta")):
            value = getattr(args, flag)
            if value is not None and (not preset or flag in argv_given or key not in cdict):
                cdict[key] = value
        if not preset or "colour_cast" in argv_given:
            cdict["colour_cast"] = args.colour_cast
        if run_cfg.method == "tfi" and "window" in cdict and "tfi_half_window" not in cdict:
            cdict["tfi_half_window"] = max(1, cdict.pop("window") // 2)
        ccfg = ClassicalConfig.from_dict(cdict, where="reconstruction settings")
        window = ccfg.window if ccfg.method == "tfp" else 2 * ccfg.tfi_half_window
        centres, step = _centres(run_cfg, src.n_frames, window)

        edict = dict(preset.get("export", {}))
        if not preset or "fps" in argv_given or "fps" not in edict:
            edict["fps"] = args.fps
        if not preset or "compression" in argv_given or "compression" not in edict:
            edict["compression"] = args.compression
        ecfg = ExportConfig.from_dict(edict, where="export settings")

        alpha = resolve_alpha(src, ccfg)
        if alpha is not None and ccfg.alpha is None:
            ccfg = ccfg.replace(alpha=[float(v) for v in alpha])  # record the estimate: the preset reproduces it
        from spikeview.classical.windows import window_range

        first = window_range(centres[0], window, src.n_frames)
        meta = ExportMetadata(source=str(src.info.path or ""), method=ccfg.method, tick_rate=src.tick_rate,
                              window=first, centre_tick=centres[0], step_ticks=step, params=ccfg.to_dict())
        frame_shape = (src.height, src.width, 3) if src.cfa is not None else (src.height, src.width)
        if out.suffix.lower() == ".mp4":
            factor = slow_motion_factor(src.tick_rate, step, ecfg.fps)
            print(f"{len(centres)} frames, one per {step} ticks, at {ecfg.fps:g} fps: {describe_slow_motion(factor)}", file=sys.stderr)
        with open_exporter(out, len(centres), frame_shape, ecfg, meta, overwrite=args.overwrite,
                           inputs=[args.preset], extra_outputs=[preset_path(out)]) as ex, \
                progress(len(centres), f"{ccfg.method} → {out.name}") as bar:
            for c, frame in zip(centres, reconstruct_frames(src, centres, ccfg, alpha=alpha)):
                ex.write(frame, window=window_range(c, window, src.n_frames), centre_tick=c)
                bar.update(1)
        _write_preset(out, args, src, run_cfg, classical=ccfg, export=ecfg)
    print(f"wrote {len(centres)} frame{'s' if len(centres) != 1 else ''} to {out}; settings in {preset_path(out)}")
    return 0


def _write_preset(out: Path, args: argparse.Namespace, src, run_cfg: RunConfig, **tables: Config) -> Path:
    import tomli_w

    from spikeview.cfa import cfa_to_str

    info = src.info
    data: dict[str, Any] = {"run": run_cfg.to_dict()}
    data["stream"] = {"format": info.format, "width": info.width, "height": info.height, "cfa": cfa_to_str(info.cfa),
                      "flip_vertical": info.flip_vertical, "flip_horizontal": info.flip_horizontal,
                      "tick_rate": info.tick_rate}
    if info.format == "npz" and getattr(args, "layout", None):
        data["stream"]["layout"] = args.layout
    for name, cfg in tables.items():
        data[name] = cfg.to_dict()
    path = preset_path(out)
    from spikeview._files import write_atomic

    return write_atomic(path, f"# spikeview reconstruct preset for {info.path}\n" + tomli_w.dumps(data), "the preset")
