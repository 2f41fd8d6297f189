"""``spikeview reconstruct … --out OUT.zarr``: the chunked, resumable batch path (in-process or on Dask).

Imported by ``spikeview --help`` for its flags only: dask and zarr are imported inside :func:`run_zarr`.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any

from spikeview.errors import ParameterError


def add_args(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("long captures (--out OUT.zarr; needs the spikeview[cluster] extra)")
    g.add_argument("--cluster", metavar="local:N|tcp://HOST:PORT",
                   help="run the chunks on N local Dask worker processes, or on the workers of a running Dask "
                        "scheduler (input and store on a file system the workers share); default: in-process")
    g.add_argument("--chunk", type=int, metavar="W",
                   help="windows per chunk: the unit of work, of resume and of the store's chunks (default 16)")
    g.add_argument("--resume", action="store_true",
                   help="finish an interrupted OUT.zarr: skip its completed chunks (flags left out come from the store)")


def wants_zarr(args: argparse.Namespace) -> bool:
    """True for an ``.zarr`` output; the batch flags with any other output are a mistake."""
    if Path(args.out).suffix.lower() == ".zarr":
        return True
    used = [f for f, v in (("--cluster", args.cluster), ("--chunk", args.chunk), ("--resume", args.resume)) if v]
    if used:
        raise ParameterError(f"{' and '.join(used)} write a Zarr store: end --out with .zarr (e.g. --out clip.zarr), "
                             "then export it with spikeview export.")
    return False


def _require_extra() -> None:
    try:
        import dask  # noqa: F401
        import distributed  # noqa: F401
        import zarr  # noqa: F401
    except ImportError as e:
        raise ParameterError(f"a .zarr output needs the cluster extra ({e.name} is missing); "
                             "install it with pip install 'spikeview[cluster]'.") from None


def _settings(args: argparse.Namespace, preset: dict[str, Any], src) -> tuple[dict[str, Any], dict[str, Any], int]:
    """``(settings, export, step)``: the recipe tables that decide the frames (as given, α not filled in)."""
    from spikeview.cfa import cfa_to_str
    from spikeview.cli.reconstruct import RunConfig, _centres
    from spikeview.export import ExportConfig

    given = set(getattr(args, "_given", ()))
    run_cfg = RunConfig.from_dict(preset.get("run", {}), where="preset [run]") if preset else RunConfig()
    if not preset or "method" in given:
        run_cfg.method = args.method
    if args.at is not None or args.range is not None:
        run_cfg.at, run_cfg.range = args.at, args.range
    info = src.info
    stream = {"format": info.format, "width": info.width, "height": info.height, "cfa": cfa_to_str(info.cfa),
              "flip_vertical": info.flip_vertical, "flip_horizontal": info.flip_horizontal, "tick_rate": info.tick_rate}
    if info.format == "npz" and getattr(args, "layout", None):
        stream["layout"] = args.layout
    settings: dict[str, Any] = {"run": run_cfg.to_dict(), "stream": stream}
    # the same flag/preset rules as the file outputs (spikeview/cli/reconstruct.py, spikeview/cli/guided.py)
    if run_cfg.method == "guided":
        from spikeview.cli.guided import _guided_config

        params = _guided_config(args, preset)
        settings["guided"] = params.to_dict()
        window = params.window
    else:
        from spikeview.classical.reconstruct import ClassicalConfig

        cdict = dict(preset.get("classical", {}))
        cdict["method"] = run_cfg.method
        if "demosaic" not in cdict and args.demosaic is None:
            cdict["demosaic"] = "malvar2004"
        for flag in ("window", "demosaic", "eta"):
            value = getattr(args, flag)
            if value is not None and (not preset or flag in given or flag not in cdict):
                cdict[flag] = value
        if not preset or "colour_cast" in given:
            cdict["colour_cast"] = args.colour_cast
        if run_cfg.method == "tfi" and "window" in cdict and "tfi_half_window" not in cdict:
            cdict["tfi_half_window"] = max(1, cdict.pop("window") // 2)
        ccfg = ClassicalConfig.from_dict(cdict, where="reconstruction settings")
        settings["classical"] = ccfg.to_dict()
        window = ccfg.window if ccfg.method == "tfp" else 2 * ccfg.tfi_half_window
    edict = dict(preset.get("export", {}))
    for key in ("fps", "compression"):
        if not preset or key in given or key not in edict:
            edict[key] = getattr(args, key)
    export = ExportConfig.from_dict(edict, where="export settings").to_dict()
    _, step = _centres(run_cfg, src.n_frames, window)
    return settings, export, step


def _open_kwargs(src) -> dict[str, Any]:
    from spikeview.cfa import cfa_to_str

    info = src.info
    kw = {"format": info.format, "width": info.width, "height": info.height, "cfa": cfa_to_str(info.cfa),
          "flip_vertical": info.flip_vertical, "flip_horizontal": info.flip_horizontal, "tick_rate": info.tick_rate}
    return kw


class _Progress:
    """tqdm on a terminal (windows, windows/s, time left); otherwise a plain line every 10 % or 30 s."""

    def __init__(self, total: int, done: int, desc: str):
        from spikeview.cli.commands import progress

        self.total, self.done, self.t0, self.last = total, done, time.perf_counter(), 0.0
        self.start_done = done
        self.tty = sys.stderr.isatty()
        self.bar = progress(total, desc, unit="window") if self.tty else None
        if self.bar is not None:
            self.bar.update(done)

    def __call__(self, n: int) -> None:
        self.done += n
        if self.bar is not None:
            self.bar.update(n)
            return
        now = time.perf_counter() - self.t0
        if now - self.last >= 30 or self.done == self.total or (self.done - n) * 10 // self.total != self.done * 10 // self.total:
            self.last = now
            rate = (self.done - self.start_done) / now if now > 0 else 0.0
            eta = (self.total - self.done) / rate if rate > 0 else float("nan")
            print(f"{self.done}/{self.total} windows, {rate:.2f} windows/s, {eta:.0f} s left", file=sys.stderr)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


def run_zarr(args: argparse.Namespace, *, cancel=None, client=None) -> int:
    """Reconstruct a range of windows into ``args.out`` (a ``.zarr`` store); see the module docstring."""
    _require_extra()
    import tomli_w

    from spikeview.cli.main import _open_from_args
    from spikeview.cli.reconstruct import _centres, _load_preset, preset_path
    from spikeview.cluster._compute import DEFAULT_CHUNK, DEFAULT_KEYFRAME, SequenceState, prepare_state
    from spikeview.cluster.run import BatchJob, parse_cluster, run_batch
    from spikeview.cluster.store import check_compatible, create_store, input_fingerprint, open_store, store_attrs

    out = Path(args.out).absolute()
    if args.chunk is not None and args.chunk < 1:
        raise ParameterError(f"--chunk {args.chunk}: use a whole number of windows >= 1, e.g. --chunk {DEFAULT_CHUNK}.")
    if args.cluster is not None:
        parse_cluster(args.cluster)  # a bad --cluster fails before any work
    attrs = None
    if out.exists() and not (getattr(args, "overwrite", False) and not args.resume):
        if not args.resume:
            raise ParameterError(f"{out.name} already exists; add --resume to finish it, --overwrite to start it "
                                 "again, or choose another --out.")
        attrs = store_attrs(open_store(out))
    preset = _load_preset(args.preset)
    if attrs is not None and not preset:
        # resume with the store's own settings; flags given explicitly must agree with them
        import tomllib

        preset = {**attrs["settings"], "export": tomllib.loads(attrs["recipe"]).get("export", {})}
    for key, value in preset.get("stream", {}).items():
        if getattr(args, key, None) is None and key in ("format", "width", "height", "cfa", "flip_vertical",
                                                          "flip_horizontal", "tick_rate", "layout"):
            setattr(args, key, value)
    chunk = args.chunk or (int(attrs["chunk"]) if attrs else DEFAULT_CHUNK)

    src = _open_from_args(args)
    with src:
        settings, export, step = _settings(args, preset, src)
        from spikeview.cli.reconstruct import RunConfig

        run_cfg = RunConfig.from_dict(settings["run"], where="settings [run]")
        from spikeview.cluster._compute import window_length

        window = window_length(settings)
        centres, step = _centres(run_cfg, src.n_frames, window)
        fingerprint = input_fingerprint(src.info.path)
        method = run_cfg.method
        table = "guided" if method == "guided" else "classical"
        if attrs is not None:
            check_compatible(out, attrs, fingerprint=fingerprint, settings=settings, chunk=chunk)
            state = SequenceState.from_dict({"alpha": attrs.get("alpha"), "white_point": attrs.get("white_point")})
        else:
            state = prepare_state(src, settings)
            recipe = {k: dict(v) for k, v in settings.items()}
            if state.alpha is not None and recipe[table].get("alpha") is None:
                recipe[table]["alpha"] = list(state.alpha)  # record the estimate: the preset reproduces it
            recipe["export"] = export
            recipe_toml = f"# spikeview reconstruct preset for {src.info.path}\n" + tomli_w.dumps(recipe)
            from spikeview.classical.windows import window_range

            windows = [window_range(c, window, src.n_frames) for c in centres]
            frame_shape = (src.height, src.width, 3 if src.cfa is not None else 1)
            create_store(out, centres=centres, windows=windows, frame_shape=frame_shape, chunk=chunk, attrs={
                "input": str(Path(src.info.path).absolute()), "fingerprint": fingerprint, "settings": settings,
                "recipe": recipe_toml, "alpha": None if state.alpha is None else list(state.alpha),
                "white_point": state.white_point, "method": method, "window": window, "step": step,
                "tick_rate": src.tick_rate, "chunk": chunk, "keyframe": DEFAULT_KEYFRAME, "n_windows": len(centres),
                "frame_shape": list(frame_shape)})
            from spikeview._files import write_atomic

            write_atomic(preset_path(out), recipe_toml, "the preset")
        job = BatchJob(input=str(Path(src.info.path).absolute()), open_kwargs=_open_kwargs(src), recipe=settings,
                       centres=tuple(int(c) for c in centres), chunk=chunk, store=str(out),
                       keyframe=int(attrs["keyframe"]) if attrs else DEFAULT_KEYFRAME)

    from spikeview.cluster.store import done_mask

    done = done_mask(open_store(out))
    done_windows = sum(job.bounds(i)[1] - job.bounds(i)[0] for i in range(job.n_chunks) if done[i])
    where = f"on {args.cluster}" if args.cluster else "in-process"
    print(f"{len(centres)} windows in {job.n_chunks} chunks of {chunk} ({method}, {where})"
          + (f"; {int(done.sum())} chunks already done" if done.any() else ""), file=sys.stderr)
    if method == "guided" and chunk % job.keyframe and job.keyframe > 1:
        from spikeview.cluster._compute import chained

        if chained(settings):
            print(f"note: --chunk {chunk} is not a multiple of the keyframe interval {job.keyframe}: chunks that start "
                  f"between keyframes recompute up to {job.keyframe - 1} lead-in windows (same frames, more time)",
                  file=sys.stderr)
    bar = _Progress(len(centres), done_windows, f"{method} → {out.name}")
    try:
        report = run_batch(job, state, cluster=args.cluster, progress=bar, cancel=cancel, client=client)
    finally:
        bar.close()
    rate = report.windows_per_second
    print(f"wrote {report.windows} window{'s' if report.windows != 1 else ''} in {report.seconds:.1f} s"
          + (f" ({rate:.2f} windows/s)" if report.windows else "")
          + f" to {out}; export with: spikeview export {out.name} --out clip.mp4")
    return 0
