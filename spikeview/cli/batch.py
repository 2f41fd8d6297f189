"""``spikeview reconstruct … --out OUT.zarr``: the chunked, resumable batch path (in-process or on Dask).

Imported by ``spikeview --help`` for its flags only: dask and zarr are imported inside :func:`run_zarr`.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from spikeview.cli._common import progress, recipe_from_args, require_extra
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


class _Progress:
    """tqdm on a terminal (windows, windows/s, time left); otherwise a plain line every 10 % or 30 s."""

    def __init__(self, total: int, done: int, desc: str):
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
    require_extra()
    from spikeview.cluster.reconstruct import reconstruct_to_store, store_recipe

    if isinstance(args.input, list):  # `reconstruct` takes several inputs; a store takes one
        if len(args.input) != 1:
            from spikeview.errors import ParameterError

            raise ParameterError("a .zarr store takes one input; run the inputs one by one.")
        args.input = args.input[0]
    out = Path(args.out).absolute()
    base = None
    if not getattr(args, "preset", None) and args.resume:
        base = store_recipe(out)  # resume with the store's settings; flags given must agree with them
    recipe = recipe_from_args(args, base)  # --preset read there (its [stream] checked against the input)
    extra = {"tag_check": args.tag_check} if getattr(args, "tag_check", None) else {}
    bar: list[_Progress] = []

    def progress(done: int, total: int) -> None:
        if not bar:
            bar.append(_Progress(total, done, f"{recipe.run.method} → {out.name}"))
        else:
            bar[0](done - bar[0].done)

    try:
        report = reconstruct_to_store(args.input, recipe, out, chunk=args.chunk, resume=args.resume,
                                      overwrite=bool(getattr(args, "overwrite", False)), cluster=args.cluster,
                                      client=client, progress=progress, cancel=cancel,
                                      notes=lambda text: print(text, file=sys.stderr), open_kwargs=extra,
                                      layout=getattr(args, "layout", None))
    finally:
        if bar:
            bar[0].close()
    if reports is not None:
        reports.append(report)
    rate = report.windows_per_second
    print(f"wrote {report.windows} window{'s' if report.windows != 1 else ''} in {report.seconds:.1f} s"
          + (f" ({rate:.2f} windows/s)" if report.windows else "")
          + f" to {out}; export with: spikeview export {args.out} --out clip.mp4")
    return 0
