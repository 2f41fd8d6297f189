"""One call for front ends: a recipe and an input path in, a finished Zarr store out.

::

    from spikeview.cluster.reconstruct import reconstruct_to_store
    report = reconstruct_to_store("capture.dat", recipe, "clip.zarr", cluster="tcp://10.1.0.5:8786",
                                  progress=lambda done, total: ..., cancel=event.is_set)

The CLI (``spikeview reconstruct … --out OUT.zarr``) and the app's export panel both call it; it
creates the store (or checks the one to resume), computes the sequence-wide state once, and runs the
chunks (:func:`spikeview.cluster.run.run_batch`).
"""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from spikeview.errors import ParameterError


def require_extra() -> None:
    """Raise one sentence when the ``cluster`` extra (dask, distributed, zarr) is not installed."""
    try:
        import dask  # noqa: F401
        import distributed  # noqa: F401
        import zarr  # noqa: F401
    except ImportError as e:
        raise ParameterError(f"a .zarr output needs the cluster extra ({e.name} is missing); "
                             "install it with pip install 'spikeview[cluster]'.") from None


def store_recipe(out: str | os.PathLike[str]):
    """The :class:`~spikeview.recipe.Recipe` a store was written with, as given (``None`` if ``out`` does not exist)."""
    from spikeview.cluster.store import check_store
    from spikeview.recipe import Recipe

    p = Path(out)
    if not p.exists():
        return None
    return Recipe.from_dict(check_store(p).attrs["settings"], where=f"{p.name} (its recipe)")


def reconstruct_to_store(input_path: str | os.PathLike[str], recipe: Any, out: str | os.PathLike[str], *,
                         chunk: int | None = None, resume: bool = False, overwrite: bool = False,
                         cluster: str | None = None, client: Any = None,
                         progress: Callable[[int, int], Any] | None = None, cancel: Callable[[], bool] | None = None,
                         notes: Callable[[str], Any] | None = None, open_kwargs: dict[str, Any] | None = None,
                         layout: str | None = None):
    """Reconstruct ``recipe``'s windows of ``input_path`` into the Zarr store ``out``.

    Args:
        input_path: the spike file (every worker must read it at this path).
        recipe: a :class:`~spikeview.recipe.Recipe` (its ``[run]`` range picks the windows; its
            ``[stream]`` how the file is read).
        out: the ``.zarr`` store.
        chunk: windows per chunk (default 16; on resume, the store's).
        resume: finish the store at ``out`` (it must come from the same input and settings).
        overwrite: replace an existing store (without ``resume``).
        cluster: ``None`` (in-process), ``"local:N"`` or a scheduler address; ``client``: a Dask client instead.
        progress: ``progress(windows_done, windows_total)`` once at the start, then as windows finish
            (inside running chunks too; on Dask at most once a second per chunk).
        cancel: polled after every finished chunk; true stops with :class:`~spikeview.errors.Cancelled`.
        notes: receives one-line messages for a person (plan of the run, notes).
        open_kwargs: extra :func:`spikeview.io.open_source` arguments (``tag_check``).
        layout: ``.npy``/``.npz`` axis order, recorded in the recipe's ``[stream]``.

    Returns:
        The :class:`~spikeview.cluster.run.BatchReport` of this call.

    Raises:
        ParameterError: bad ``chunk``/``cluster``; ``out`` exists (without ``resume``/``overwrite``);
            a store of another input or other settings; a worker that died repeatedly.
    """
    require_extra()
    from spikeview.cluster._compute import DEFAULT_CHUNK
    from spikeview.cluster.run import connect, parse_cluster
    from spikeview.cluster.store import check_store

    say = notes if notes is not None else (lambda text: None)
    out = Path(out).absolute()
    if out.suffix.lower() != ".zarr":
        raise ParameterError(f"{out.name}: a batch reconstruction writes a Zarr store; end the name with .zarr.")
    if chunk is not None and chunk < 1:
        raise ParameterError(f"--chunk {chunk}: use a whole number of windows >= 1, e.g. --chunk {DEFAULT_CHUNK}.")
    if cluster is not None:
        parse_cluster(cluster)  # bad text fails before any work
    if resume and not out.exists():
        raise ParameterError(f"{out.name} does not exist, so there is nothing to resume; leave --resume out to start it.")
    attrs = None
    if out.exists() and not (overwrite and not resume):
        if not resume:
            raise ParameterError(f"{out.name} already exists; add --resume to finish it, --overwrite to start it "
                                 "again, or choose another --out.")
        attrs = check_store(out).attrs  # every attribute checked before it is trusted
    elif not out.parent.is_dir():
        from spikeview.errors import OutputFileError

        raise OutputFileError(f"{out}: the folder {out.parent} does not exist; create it or choose another output path.")
    elif not os.access(out.parent, os.W_OK | os.X_OK):
        from spikeview.errors import OutputFileError

        raise OutputFileError(f"{out}: the folder {out.parent} is read-only; choose a folder you can write to with --out.")
    chunk = chunk or (int(attrs["chunk"]) if attrs else DEFAULT_CHUNK)
    where = f"on {cluster}" if cluster else ("on the given Dask client" if client is not None else "in-process")
    close = None
    if cluster is not None and client is None:
        client, close = connect(cluster)  # an unreachable scheduler fails before the store is made
    try:
        return _run(input_path, recipe, out, chunk, attrs, client, progress, cancel, say,
                    {**recipe.stream.open_kwargs(), **(open_kwargs or {})}, layout, where)
    finally:
        if close is not None:
            close()


def _available_memory() -> int | None:
    """Bytes of memory available to a new allocation (Linux ``MemAvailable``; ``None`` elsewhere)."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        return None
    return None


def _check_chunk_memory(chunk: int, frame_shape: tuple[int, int, int]) -> None:
    """Refuse a chunk whose frames alone (held twice while a chunk is stacked) exceed the memory available."""
    from spikeview._files import human_bytes
    from spikeview.cluster._compute import DEFAULT_CHUNK

    need = 2 * chunk * int(np.prod(frame_shape)) * 4
    avail = _available_memory()
    if avail is not None and need > avail:
        h, w, _ = frame_shape
        raise ParameterError(f"--chunk {chunk}: a chunk of {chunk} windows of {w}x{h} needs about {human_bytes(need)}, "
                             f"more than the {human_bytes(avail)} of memory available; use a smaller --chunk "
                             f"(e.g. --chunk {DEFAULT_CHUNK}).")


def _discard_unstarted(out: Path) -> bool:
    """Remove a store this call created when no chunk of it is done (and its preset); ``True`` if removed."""
    import shutil

    from spikeview.cluster.store import check_store

    try:
        if check_store(out).done.any():
            return False  # resumable: keep it
    except Exception:  # noqa: BLE001 - a store that failed while being created is not worth keeping
        pass
    shutil.rmtree(out, ignore_errors=True)
    out.with_name(out.name + ".preset.toml").unlink(missing_ok=True)
    return True


def _run(input_path, recipe, out: Path, chunk: int, attrs, client, progress, cancel, say, kwargs, layout, where):
    """Create (or check) the store and run its chunks; a run that fails leaves a resumable store or nothing."""
    from spikeview._files import os_error_sentence
    from spikeview.errors import OutputFileError, SpikeviewError

    created = [False]
    try:
        return _run_store(input_path, recipe, out, chunk, attrs, client, progress, cancel, say, kwargs, layout, where,
                          created)
    except BaseException as e:
        removed = created[0] and _discard_unstarted(out)  # nothing done yet: leave nothing behind
        if isinstance(e, OSError) and not isinstance(e, SpikeviewError):
            kept = not removed and out.exists() and (created[0] or attrs is not None)
            raise OutputFileError(f"cannot write {out.name}: {os_error_sentence(e)}"
                                  + ("; the finished chunks are kept, --resume continues" if kept else "") + ".") from None
        raise


def _run_store(input_path, recipe, out: Path, chunk: int, attrs, client, progress, cancel, say, kwargs, layout, where,
               created: list[bool]):
    from spikeview._files import write_atomic
    from spikeview.classical.windows import window_range
    from spikeview.cluster._compute import DEFAULT_KEYFRAME, chained, state_from_attrs, state_to_attrs
    from spikeview.cluster.run import BatchJob, run_batch
    from spikeview.cluster.store import check_compatible, check_store, create_store, input_fingerprint, repair_markers
    from spikeview.errors import InputFileError
    from spikeview.io import open_source
    from spikeview.pipeline import prepare_sequence, recipe_for_state, white_point_line, window_centres
    from spikeview.recipe import StreamTable

    from spikeview.classical.calibration import attach

    with attach(open_source(input_path, **kwargs), recipe.stream.camera) as src:
        stream = StreamTable.from_info(src.info, layout).to_dict()
        recipe = recipe.with_values({f"stream.{k}": v for k, v in stream.items()})
        settings = recipe.to_dict()
        centres, step = window_centres(recipe, src.n_frames)
        chunk = min(chunk, len(centres))  # a chunk never holds more windows than the run (--chunk 1000000000)
        window = recipe.span()
        method = recipe.run.method
        fingerprint = input_fingerprint(src.info.path)
        frame_shape = (src.height, src.width, 3 if src.cfa is not None else 1)
        if attrs is not None:
            check_compatible(out, attrs, fingerprint=fingerprint, settings=settings, chunk=chunk)
            state = state_from_attrs(attrs)
            _check_chunk_memory(chunk, frame_shape)
        else:
            _check_chunk_memory(chunk, frame_shape)
            state = prepare_sequence(src, recipe)
            full = recipe_for_state(recipe, state, src)  # α, the display curve recorded: the preset reproduces the frames
            recipe_toml = f"# spikeview reconstruct preset for {src.info.path}\n" + full.to_toml()
            windows = [window_range(c, window, src.n_frames) for c in centres]
            created[0] = True
            create_store(out, centres=centres, windows=windows, frame_shape=frame_shape, chunk=chunk, attrs={
                "input": str(Path(src.info.path).absolute()), "fingerprint": fingerprint, "settings": settings,
                "recipe": recipe_toml, **state_to_attrs(state), "method": method, "window": window, "step": step,
                "tick_rate": float(src.tick_rate), "chunk": chunk, "keyframe": DEFAULT_KEYFRAME,
                "n_windows": len(centres), "frame_shape": list(frame_shape)})
            write_atomic(out.with_name(out.name + ".preset.toml"), recipe_toml, "the preset")
        given = recipe.export.white is not None and recipe.export.white != state.white
        say(white_point_line(recipe, state, "recorded in the store" if attrs is not None else (
            "set by --white or the preset" if given else state.white_how)))
        job = BatchJob(input=str(Path(src.info.path).absolute()), open_kwargs=kwargs, recipe=settings,
                       centres=tuple(int(c) for c in centres), chunk=chunk, store=str(out),
                       keyframe=int(attrs["keyframe"]) if attrs else DEFAULT_KEYFRAME)

    check = check_store(out)
    if attrs is not None:
        # a chunk marked done whose frames cannot be decoded, or whose marker is unreadable, is recomputed
        redo = []
        for i in np.flatnonzero(check.done):
            try:
                check.read_chunk(int(i))
            except InputFileError:
                redo.append(int(i))
        again = sorted(set(redo) | set(check.unreadable)) if not check.markers_lost else []
        if check.seconds_lost and not (redo or check.unreadable or check.markers_lost):
            repair_markers(check, [])  # the timings array only: nothing to recompute
        elif redo or check.unreadable or check.markers_lost:
            repair_markers(check, redo)
            say(f"note: {out.name}: " + ("its completion markers are missing or unreadable; every chunk is recomputed"
                                         if check.markers_lost else
                                         f"recomputing chunk(s) {', '.join(map(str, again))}: their frames or completion "
                                         "markers cannot be read") + ".")
    done = check.done
    total = len(centres)
    n_done = sum(job.bounds(i)[1] - job.bounds(i)[0] for i in range(job.n_chunks) if done[i])
    say(f"{total} windows in {job.n_chunks} chunks of {chunk} ({method}, {where})"
        + (f"; {int(done.sum())} chunks already done" if done.any() else ""))
    if chunk % job.keyframe and chained(settings):
        say(f"note: --chunk {chunk} is not a multiple of the keyframe interval {job.keyframe}: chunks that start "
            f"between keyframes recompute up to {job.keyframe - 1} lead-in windows (same frames, more time).")

    def on_chunk(n: int) -> None:
        if progress is not None:
            progress(n_done + n, total)

    if progress is not None:
        progress(n_done, total)
    return run_batch(job, state, progress=on_chunk, cancel=cancel, client=client)
