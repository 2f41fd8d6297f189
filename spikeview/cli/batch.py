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


def _recipe(args: argparse.Namespace, base):
    """``base`` ← the geometry flags ← the recipe flags given ← ``--at``/``--range`` (as ``recipe_from_args``)."""
    from spikeview.cli.reconstruct import STREAM_FLAGS
    from spikeview.recipe import apply_flags

    recipe = base
    stream = {k: getattr(args, k) for k in STREAM_FLAGS if getattr(args, k, None) is not None}
    if stream:
        recipe = recipe.with_values({f"stream.{k}": v for k, v in stream.items()})
    recipe = apply_flags(recipe, args)
    if getattr(args, "at", None) is not None or getattr(args, "range", None) is not None:
        recipe = recipe.with_values({"run.at": args.at, "run.range": args.range})
    return recipe


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


def run_zarr(args: argparse.Namespace, *, cancel=None, client=None, reports: list | None = None) -> int:
    """Reconstruct a range of windows into ``args.out`` (a ``.zarr`` store); see the module docstring.

    ``cancel`` is polled after every finished chunk; ``client`` is a Dask client to use instead of
    ``--cluster``; the run's :class:`~spikeview.cluster.run.BatchReport` is appended to ``reports``.
    """
    _require_extra()
    from spikeview._files import write_atomic
    from spikeview.classical.windows import window_range
    from spikeview.cli.reconstruct import open_stream, preset_path
    from spikeview.cluster._compute import DEFAULT_CHUNK, DEFAULT_KEYFRAME, chained, state_from_attrs, state_to_attrs
    from spikeview.cluster.run import BatchJob, parse_cluster, run_batch
    from spikeview.cluster.store import (
        check_compatible,
        create_store,
        done_mask,
        input_fingerprint,
        open_store,
        store_attrs,
    )
    from spikeview.pipeline import prepare_sequence, recipe_for_state, window_centres
    from spikeview.recipe import Recipe, StreamTable

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
    if getattr(args, "preset", None):
        base = Recipe.load(args.preset)
    elif attrs is not None:
        base = Recipe.from_dict(attrs["settings"], where=f"{out.name} (its recipe)")  # flags given must agree with it
    else:
        base = Recipe()
    recipe = _recipe(args, base)
    chunk = args.chunk or (int(attrs["chunk"]) if attrs else DEFAULT_CHUNK)

    src = open_stream(args, recipe)
    with src:
        stream = StreamTable.from_info(src.info, getattr(args, "layout", None)).to_dict()
        recipe = recipe.with_values({f"stream.{k}": v for k, v in stream.items()})
        settings = recipe.to_dict()
        centres, step = window_centres(recipe, src.n_frames)
        window = recipe.span()
        method = recipe.run.method
        fingerprint = input_fingerprint(src.info.path)
        if attrs is not None:
            check_compatible(out, attrs, fingerprint=fingerprint, settings=settings, chunk=chunk)
            state = state_from_attrs(attrs)
        else:
            state = prepare_sequence(src, recipe)
            full = recipe_for_state(recipe, state)  # the α estimate recorded: the preset reproduces the frames
            recipe_toml = f"# spikeview reconstruct preset for {src.info.path}\n" + full.to_toml()
            windows = [window_range(c, window, src.n_frames) for c in centres]
            frame_shape = (src.height, src.width, 3 if src.cfa is not None else 1)
            create_store(out, centres=centres, windows=windows, frame_shape=frame_shape, chunk=chunk, attrs={
                "input": str(Path(src.info.path).absolute()), "fingerprint": fingerprint, "settings": settings,
                "recipe": recipe_toml, **state_to_attrs(state), "method": method, "window": window, "step": step,
                "tick_rate": float(src.tick_rate), "chunk": chunk, "keyframe": DEFAULT_KEYFRAME,
                "n_windows": len(centres), "frame_shape": list(frame_shape)})
            write_atomic(preset_path(out), recipe_toml, "the preset")
        open_kwargs = recipe.stream.open_kwargs()
        if getattr(args, "tag_check", None):
            open_kwargs["tag_check"] = args.tag_check
        job = BatchJob(input=str(Path(src.info.path).absolute()), open_kwargs=open_kwargs, recipe=settings,
                       centres=tuple(int(c) for c in centres), chunk=chunk, store=str(out),
                       keyframe=int(attrs["keyframe"]) if attrs else DEFAULT_KEYFRAME)

    done = done_mask(open_store(out))
    done_windows = sum(job.bounds(i)[1] - job.bounds(i)[0] for i in range(job.n_chunks) if done[i])
    where = f"on {args.cluster}" if args.cluster else ("on the given Dask client" if client is not None else "in-process")
    print(f"{len(centres)} windows in {job.n_chunks} chunks of {chunk} ({method}, {where})"
          + (f"; {int(done.sum())} chunks already done" if done.any() else ""), file=sys.stderr)
    if chunk % job.keyframe and chained(settings):
        print(f"note: --chunk {chunk} is not a multiple of the keyframe interval {job.keyframe}: chunks that start "
              f"between keyframes recompute up to {job.keyframe - 1} lead-in windows (same frames, more time).",
              file=sys.stderr)
    bar = _Progress(len(centres), done_windows, f"{method} → {out.name}")
    try:
        report = run_batch(job, state, cluster=args.cluster, progress=bar, cancel=cancel, client=client)
    finally:
        bar.close()
    if reports is not None:
        reports.append(report)
    rate = report.windows_per_second
    print(f"wrote {report.windows} window{'s' if report.windows != 1 else ''} in {report.seconds:.1f} s"
          + (f" ({rate:.2f} windows/s)" if report.windows else "")
          + f" to {out}; export with: spikeview export {out.name} --out clip.mp4")
    return 0
