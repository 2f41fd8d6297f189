"""``spikeview reconstruct --method guided``: the SpikeDiff sampler from the command line."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

#: command-line flag → GuidedConfig field
FLAG_TO_FIELD = {"prior": "prior", "model": "model_path", "guidance": "guidance", "s": "s", "k": "k",
                 "levels": "levels", "t_start": "t_start", "steps": "steps", "seed": "seed", "window": "window",
                 "eta": "eta", "warm_start": "warm_start", "demosaic": "demosaic"}


def add_args(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("guided reconstruction (--method guided; defaults from the built-in tuned settings)")
    g.add_argument("--prior", choices=["ffdnet", "sd"], help="natural-image prior: embedded FFDNet (default) or a local Stable Diffusion model")
    g.add_argument("--model", metavar="PATH", help="diffusers-format model folder for --prior sd")
    g.add_argument("--guidance", choices=["hqs", "dps"], help="guidance rule: hqs (default, no backprop through the prior) or dps")
    g.add_argument("--s", type=float, help="DPS guidance strength s")
    g.add_argument("--k", type=float, help="soft-quantisation sharpness k (paper: 50)")
    g.add_argument("--levels", type=int, help="Laplacian pyramid levels L of the multiscale loss (capped by frame size)")
    g.add_argument("--t-start", type=float, help="start noise level sigma (fraction of full scale, at most 75/255 = 0.294)")
    g.add_argument("--steps", type=int, help="number of sampler steps")
    g.add_argument("--seed", type=int, help="random seed (same seed and machine: same result)")
    g.add_argument("--warm-start", action=argparse.BooleanOptionalAction, default=None,
                   help="start each window from the previous result (video)")


def _guided_config(args: argparse.Namespace, preset: dict[str, Any]):
    from spikeview.guided import GuidedConfig

    data = dict(preset.get("guided", {}))
    given = set(getattr(args, "_given", ()))
    for flag, field in FLAG_TO_FIELD.items():
        value = getattr(args, flag, None)
        if value is None:
            continue
        if flag in ("window", "demosaic", "eta") and flag not in given:
            continue  # the classical defaults of these flags do not apply to the guided sampler
        if preset and flag not in given and field in data:
            continue
        data[field] = value
    return GuidedConfig.from_dict(data, where="guided settings")


def reconstruct_guided(args: argparse.Namespace, src, run_cfg, preset: dict[str, Any], out: Path) -> int:
    from spikeview.classical.windows import window_range
    from spikeview.cli.commands import progress
    from spikeview.cli.reconstruct import _centres, _write_preset, preset_path
    from spikeview.export import ExportConfig, ExportMetadata, describe_slow_motion, open_exporter, slow_motion_factor
    from spikeview.guided import GuidedSampler, Observation, make_plan, reconstruct_sequence, resolve_alpha

    params = _guided_config(args, preset)
    edict = dict(preset.get("export", {}))
    given = set(getattr(args, "_given", ()))
    for key in ("fps", "compression"):
        if not preset or key in given or key not in edict:
            edict[key] = getattr(args, key)
    ecfg = ExportConfig.from_dict(edict, where="export settings")
    centres, step = _centres(run_cfg, src.n_frames, params.window)

    alpha = resolve_alpha(src, params)
    if alpha is not None and params.alpha is None:
        params = params.replace(alpha=[float(v) for v in alpha])  # one α per sequence, recorded in the preset
    obs = Observation.from_source(src, centres[0], params.window, alpha=alpha, eta=params.eta)
    print(make_plan(obs, params), file=sys.stderr)

    frame_shape = (src.height, src.width, 3) if src.cfa is not None else (src.height, src.width)
    meta = ExportMetadata(source=str(src.info.path or ""), method="guided", tick_rate=src.tick_rate,
                          window=window_range(centres[0], params.window, src.n_frames), centre_tick=centres[0],
                          step_ticks=step, params=params.to_dict())
    if out.suffix.lower() == ".mp4":
        print(f"{len(centres)} frames, one per {step} ticks, at {ecfg.fps:g} fps: "
              f"{describe_slow_motion(slow_motion_factor(src.tick_rate, step, ecfg.fps))}", file=sys.stderr)
    sampler = GuidedSampler(params)
    with open_exporter(out, len(centres), frame_shape, ecfg, meta, overwrite=getattr(args, "overwrite", False),
                       inputs=[getattr(args, "preset", None)], extra_outputs=[preset_path(out)]) as ex, \
            progress(len(centres) * max(1, params.steps), f"guided → {out.name}", unit="step") as bar:
        def on_step(fi: int, n: int, step_i: int, total: int, preview) -> None:
            bar.update(1)

        frames = reconstruct_sequence(src, centres, params, alpha=alpha, callback=on_step, sampler=sampler)
        for c, frame in zip(centres, frames):
            ex.write(frame, window=window_range(c, params.window, src.n_frames), centre_tick=c)
    _write_preset(out, args, src, run_cfg, guided=params, export=ecfg)
    print(f"wrote {len(centres)} frame{'s' if len(centres) != 1 else ''} to {out}; settings in {preset_path(out)}")
    return 0
