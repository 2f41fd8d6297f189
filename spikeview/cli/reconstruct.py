"""``spikeview reconstruct``: spikes → frames → export, with a reproducible preset.

The settings are one :class:`~spikeview.recipe.Recipe`: the defaults, then ``--preset FILE`` (a
recipe TOML, e.g. the ``<out>.preset.toml`` every run writes beside its outputs, or one the app
saved), then the flags given on the command line (generated from :data:`spikeview.recipe.PARAMS`).
The frames come from :func:`spikeview.pipeline.write_sequence`, the same function the app's export
calls, so the same recipe gives the same pixels in both.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from spikeview.cli import batch
from spikeview.cli._common import add_overwrite_flag, open_source_from_args, preset_path, progress, recipe_from_args
from spikeview.recipe import BY_PATH, PARAMS, Recipe, StreamTable, add_flags, given_flags

#: the command reads a spike file: the geometry flags are added (:func:`spikeview.cli._common.add_geometry_flags`)
GEOMETRY = True
EPILOG = (
    "examples:\n"
    "  spikeview reconstruct demo.dat --method tfp --at 1000 --out frame.png\n"
    "  spikeview reconstruct demo.dat --method tfi --range 0:2000:20 --out frames/f_%04d.exr\n"
    "  spikeview reconstruct demo.dat --range 0:4000:10 --out clip.mp4 --fps 30\n"
    "  spikeview reconstruct demo.dat --method guided --at 1000 --out guided.exr\n"
    "  spikeview reconstruct demo.dat --method guided --guidance dps --s 0.5 --steps 20 --range 0:400:40 --out g_%04d.exr\n"
    "  spikeview reconstruct demo.dat --preset guided.exr.preset.toml --out again.exr\n"
    "  spikeview reconstruct demo.dat --range 0:40000:20 --out clip.zarr --cluster local:2   (then --resume)\n"
)


def add_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("input", metavar="INPUT", nargs="+",
                   help="spike file (.dat, raw camera stream, .npy/.npz); several files, or a folder of captures, are "
                        "reconstructed one after another with the same settings, one output each (--out then names a folder)")
    when = p.add_mutually_exclusive_group()
    when.add_argument("--at", type=int, metavar="T", help="reconstruct the one window centred on tick T")
    when.add_argument("--range", metavar="A:B[:STEP]",
                      help="windows centred on A, A+STEP, ... below B (STEP defaults to the window length)")
    p.add_argument("--out", metavar="OUT",
                   help="output: .npy, .mp4, or an .exr/.png pattern with a frame number such as frame_%%04d.exr "
                        "(default: INPUT's name, the method and the tick(s) in the current folder, e.g. big_guided_t100.exr "
                        "for --at, big_tfp_0-2000.mp4 for --range; an existing file is never replaced without --overwrite: "
                        "the next free name _2, _3, ... is taken)")
    p.add_argument("--preset", metavar="FILE",
                   help="a recipe TOML (written beside earlier outputs, or saved by the app) to re-run; flags given override it")
    add_overwrite_flag(p)
    add_flags(p, ("run", "classical", "guided", "export"))
    batch.add_args(p)


def display_curve_line(out: Path, asked: str, source: Any) -> str | None:
    """The one line about the display curve of an 8-bit output (PNG/MP4) whose curve comes from the capture
    (``asked`` = ``export.transfer`` before it was resolved: ``auto``, the default), which curve and why
    (:func:`spikeview.transfer.resolve_transfer`); ``None`` for other outputs and a curve the user chose."""
    from spikeview.transfer import resolve_transfer

    if out.suffix.lower() not in (".png", ".mp4") or asked != "auto":
        return None
    curve, why = resolve_transfer("auto", source.info)
    return f"display curve {curve} ({why})."


def inactive_notes(recipe: Recipe, args: argparse.Namespace, source: Any, centre: int, state: Any,
                   asked_precision: str | None = None) -> tuple[list[str], Any]:
    """One sentence for every flag the user gave that cannot act on this run (and why), and the first
    window's observation when the plan was printed (the run reuses it; ``None`` otherwise).
    ``asked_precision``: ``guided.precision`` as given (``auto``), shown in the plan (the recipe holds
    what it resolved to, the same arithmetic)."""
    given = given_flags(args)
    notes = []
    if recipe.run.method != "guided":
        for path in sorted(given):
            if path.startswith("guided."):
                notes.append(f"{BY_PATH[path].flag} applies to --method guided only; it is ignored by --method {recipe.run.method}.")
        return notes, None
    from spikeview.pipeline import plan_window

    # the plan of the settings the sampler runs (η at the sequence's exposure), as the app shows it
    wp = plan_window(source, recipe, centre, state=state, precision="auto" if asked_precision == "auto" else None)
    print(wp.plan, file=sys.stderr)
    for path, why in wp.knobs.items():
        if why and path in given:
            notes.append(f"{BY_PATH[path].flag} has no effect here: {why}.")
    return notes, wp.whole


def default_out(args: argparse.Namespace, recipe: Recipe) -> Path:
    """The output when ``--out`` is not given: ``<INPUT stem>_<method>_t<T>.exr`` for one window,
    ``<stem>_<method>_<A>-<B>.mp4`` for ``--range A:B[:STEP]``, in the current folder (the input's
    folder may be read-only). A name whose output or preset exists is passed over for the next free
    ``_2``, ``_3``, ... unless ``--overwrite`` is given: a run without ``--out`` never replaces a file."""
    from spikeview.export import output_stem

    if recipe.run.range is not None:
        a, b = (recipe.run.range.split(":") + [""])[:2]
        base, suffix = output_stem(args.input, recipe.run.method, span=(a or 0, b or "end")), ".mp4"
    else:
        base, suffix = output_stem(args.input, recipe.run.method, tick=recipe.run.at), ".exr"
    out = Path(base + suffix)
    if getattr(args, "overwrite", False):
        return out
    n = 2
    while out.exists() or preset_path(out).exists():
        out = Path(f"{base}_{n}{suffix}")
        n += 1
    return out


#: what a folder given as INPUT contributes: its spike captures (not sidecars, ground truth or outputs)
CAPTURE_SUFFIXES = (".dat", ".npy", ".npz", ".raw", ".bin")


def _inputs(names: list[str]) -> list[Path]:
    """The captures ``names`` list: files as given, a folder's captures (sorted; not its ``.gt.npz`` ground truths)."""
    from spikeview.errors import ParameterError

    out: list[Path] = []
    for n in names:
        p = Path(n)
        if p.is_dir():
            # not a camera profile's maps (``cam.npz`` beside ``cam.toml``, spikeview calibrate's pair)
            found = sorted(q for q in p.iterdir() if q.is_file() and q.suffix.lower() in CAPTURE_SUFFIXES
                           and not q.name.endswith((".gt.npz",)) and not q.name.endswith(".preset.npz")
                           and not (q.suffix.lower() == ".npz" and q.with_suffix(".toml").is_file()))
            if not found:
                raise ParameterError(f"{n}: the folder holds no spike capture ({', '.join(CAPTURE_SUFFIXES)}); name the files instead.")
            out += found
        else:
            out.append(p)
    return out


def run(args: argparse.Namespace) -> int:
    """One capture, or several one after another (one output each; a failed one is said and the others still run)."""
    import copy

    from spikeview.errors import ParameterError, SpikeviewError

    names = args.input if isinstance(args.input, list) else [args.input]
    if len(names) == 1 and not Path(names[0]).is_dir():
        args.input = names[0]
        return _run_one(args)
    inputs = _inputs(names)
    folder = None
    if args.out is not None:
        folder = Path(args.out)
        if not folder.is_dir():
            raise ParameterError(f"--out {args.out}: with several inputs --out names an existing folder for their outputs "
                                 "(each takes its input's name); create it first.")
    if batch.wants_zarr(args):
        raise ParameterError("a .zarr store takes one input; run the inputs one by one.")
    failed = 0
    from collections import Counter

    stems = Counter(p.stem for p in inputs)  # captures of one name from several folders: their outputs take the folder's
    taken: set[str] = set()
    for i, path in enumerate(inputs, 1):
        one = copy.copy(args)
        one.input = str(path)
        one.out = None
        print(f"[{i}/{len(inputs)}] {path}", file=sys.stderr)
        try:
            if folder is not None:
                name = default_out(one, recipe_from_args(one)).name
                if stems[path.stem] > 1:
                    name = f"{path.resolve().parent.name}_{name}"
                stem, suffix, k = Path(name).stem, Path(name).suffix, 2
                while name in taken:  # still one name for two inputs (a.npy and a.npz of one folder): _2, _3, ...
                    name, k = f"{stem}_{k}{suffix}", k + 1
                taken.add(name)
                one.out = str(folder / name)
            _run_one(one)
        except SpikeviewError as e:
            failed += 1
            msg = str(e)
            print(f"spikeview: error: {msg if str(path) in msg else f'{path}: {msg}'}", file=sys.stderr)
    if failed:
        print(f"spikeview: {failed} of {len(inputs)} inputs failed (said above); the others were written." if failed < len(inputs)
              else f"spikeview: all {len(inputs)} inputs failed (said above); nothing was written.", file=sys.stderr)
        return 1
    return 0


def _run_one(args: argparse.Namespace) -> int:
    chosen = args.out is None
    recipe = recipe_from_args(args) if chosen else None
    if chosen:
        args.out = str(default_out(args, recipe))
    if batch.wants_zarr(args):  # a .zarr output: the chunked, resumable batch path
        return batch.run_zarr(args)
    from spikeview.export import describe_slow_motion, slow_motion_factor
    from spikeview.pipeline import prepare_sequence, recipe_for_state, tfi_half_window, white_balance_line, white_point_line, window_centres, write_sequence
    from spikeview.classical.colour_cast import WHITE_LOW_COUNT
    from spikeview.pipeline import WriteOptions

    recipe = recipe if recipe is not None else recipe_from_args(args)
    out = Path(args.out)
    _check_output_first(out, args)
    src = open_source_from_args(args, recipe, writes=True)
    if chosen:  # once the input is known to be a capture
        print(f"no --out given: writing {out} in the current folder (--out NAME.png for an 8-bit image)", file=sys.stderr)
    with src:
        recipe = recipe.with_values({f"stream.{k}": v for k, v in StreamTable.from_info(src.info, getattr(args, "layout", None)).to_dict().items()})
        centres, step = window_centres(recipe, src.n_frames)
        from spikeview.export import check_output_name

        check_output_name(out, len(centres))  # e.g. several PNG frames without a %04d field: said first
        from spikeview.classical.windows import window_range

        window_range(centres[0], recipe.classical.window, src.n_frames)  # a window the stream cannot hold: said first
        if recipe.run.range is not None:
            a, b, _ = _parse(recipe.run.range, step)
            if b > src.n_frames:
                print(f"note: --range {recipe.run.range} ends past the stream's last tick ({src.n_frames - 1}); "
                      f"the last window is centred on tick {centres[-1]}.", file=sys.stderr)
        state = prepare_sequence(src, recipe)
        asked_precision = recipe.guided.precision
        asked_transfer = recipe.export.transfer
        recipe = recipe_for_state(recipe, state, src)
        how = "set by --white" if "export.white" in given_flags(args) else (
            "from the preset" if getattr(args, "preset", None) and state.white is not None and
            recipe.export.white != state.white else state.white_how)
        print(white_point_line(recipe, state, how), file=sys.stderr)
        line = white_balance_line(state)
        if line is not None:
            print(line, file=sys.stderr)
        line = display_curve_line(out, asked_transfer, src)
        if line is not None:
            print(line, file=sys.stderr)
        notes, first = inactive_notes(recipe, args, src, centres[0], state, asked_precision)
        for note in notes:
            print(f"note: {note}", file=sys.stderr)
        if recipe.run.method == "tfp" and state.exposure_white is not None:
            # the white point needed longer windows: a classical frame of this window is a few single spikes
            print(f"note: a dark capture for a {recipe.classical.window}-tick window (it holds under "
                  f"{WHITE_LOW_COUNT:g} spikes where the scene is white), so each TFP frame is "
                  "mostly single spikes; --method guided pools the neighbouring windows where the scene is still, or a "
                  "longer --window averages more ticks.", file=sys.stderr)
        reach = tfi_half_window(recipe.classical.tfi_half_window, state)
        if recipe.run.method == "tfi" and reach > recipe.classical.tfi_half_window:
            print(f"note: a dark capture, so TFI searches ±{reach} ticks around each frame's tick, not "
                  f"±{recipe.classical.tfi_half_window} (--tfi-half-window): its darker parts fire less than once in "
                  f"{2 * recipe.classical.tfi_half_window} ticks, and a shorter search shows them all at one flat level.",
                  file=sys.stderr)
        if out.suffix.lower() == ".mp4" and recipe.run.at is None and recipe.run.range is None:
            print(f"note: no --at or --range, so the video holds one frame (the window at tick {centres[0]}); pass "
                  f"--range 0:{src.n_frames} for the whole capture.", file=sys.stderr)
        if out.suffix.lower() == ".mp4":
            factor = slow_motion_factor(src.tick_rate, step, recipe.export.fps)
            print(f"{len(centres)} frames, one per {step} ticks, at {recipe.export.fps:g} fps: {describe_slow_motion(factor)}",
                  file=sys.stderr)
        guided = recipe.run.method == "guided"
        total = len(centres) * (max(1, recipe.guided.steps) if guided else 1)
        begun = [0]  # the index of the latest frame begun: the frames before it are written
        with progress(total, f"{recipe.run.method} → {out.name}", unit="step" if guided else "frame") as bar:
            def on_step(fi: int, n: int, step_i: int, steps: int, preview: Any) -> None:
                bar.update(1)
                begun[0] = max(begun[0], fi)

            try:
                write_sequence(src, recipe, centres, out, WriteOptions(
                    state=state, step=step, callback=on_step, overwrite=bool(getattr(args, "overwrite", False)),
                    inputs=[getattr(args, "preset", None)], extra_outputs=[preset_path(out)],
                    announce=lambda text: print(text, file=sys.stderr), first_observation=first))
            except BaseException:
                if "%" in out.name and begun[0] > 0:  # a stopped sequence keeps its finished frames: and their recipe
                    try:
                        _write_preset(out, recipe, src)
                    except Exception:  # noqa: BLE001 - the run's own error is the one to report
                        pass
                raise
        _write_preset(out, recipe, src)
    _say_stale_frames(out, len(centres), recipe.export.first_frame)
    at = "" if len(centres) != 1 else (f" (the window centred on tick {centres[0]}"
                                       + (", the middle of the capture: --at T for another)" if getattr(args, "at", None) is None
                                          and not getattr(args, "range", None) and not getattr(args, "preset", None) else ")"))
    print(f"wrote {len(centres)} frame{'s' if len(centres) != 1 else ''}{at} to {out}; settings in {preset_path(out)}")
    return 0


def _say_stale_frames(out: Path, n: int, first: int) -> None:
    """A frame sequence written over an earlier, longer one (``--overwrite``) leaves that run's later frames beside
    its own: say so (they would be read as one sequence) rather than delete files no one named."""
    if "%" not in out.name:
        return
    from spikeview.export.base import existing_frame_files

    ours = {out.with_name(out.name % (first + i)).name for i in range(n)}
    stale = [p for p in existing_frame_files(out) if p.name not in ours]
    if stale:
        print(f"spikeview: warning: {len(stale)} file{'s' if len(stale) != 1 else ''} named like {stale[0].name} in "
              f"{out.parent} {'are' if len(stale) != 1 else 'is'} from an earlier run (this one wrote {n}); delete "
              f"{'them' if len(stale) != 1 else 'it'} if the sequence should end at its last frame.", file=sys.stderr)


def _check_output_first(out: Path, args: argparse.Namespace) -> None:
    """The output's format and the files it would replace, checked before any informational line (the
    exporter checks again when it opens; nothing is written here)."""
    from spikeview._files import check_writable
    from spikeview.errors import ParameterError
    from spikeview.export import SUFFIXES

    raw = str(args.out)
    if not raw.strip() or raw.endswith(("/", "\\")):  # an existing folder: check_writable names it
        raise ParameterError(f"--out {raw!r} names no file; give a file name such as frame.exr, clip.mp4 or "
                             "frames/f_%04d.png (the folder must exist).")
    if out.suffix.lower() not in SUFFIXES:
        raise ParameterError(f"{out}: unknown export format {out.suffix or '(no suffix)'!r}; end the name with "
                             f"{', '.join(SUFFIXES[:-1])} or {SUFFIXES[-1]}.")
    from spikeview.export.base import check_output_folder

    check_output_folder(out)  # a missing or unwritable folder, before the white point is printed
    overwrite = bool(getattr(args, "overwrite", False))
    inputs = [getattr(args, "input", None), getattr(args, "preset", None)]
    if "%" not in out.name:
        check_writable(out, overwrite, inputs)
    check_writable(preset_path(out), overwrite, inputs, owner=None if "%" in out.name else out)


def _parse(text: str, step: int) -> tuple[int, int, int]:
    from spikeview.pipeline import parse_range

    return parse_range(text, step)


def _write_preset(out: Path, recipe: Recipe, src: Any) -> Path:
    """The recipe beside the output (``<out>.preset.toml``; checked with the output before any work:
    never an input, replaced only with ``--overwrite``); ``--preset`` re-runs it exactly."""
    path = preset_path(out)
    return recipe.save(path, header=f"# spikeview reconstruct preset for {src.info.path}")


__all__ = ["PARAMS", "preset_path", "recipe_from_args", "run"]
