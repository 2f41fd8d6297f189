"""Simulate straight to files: the plain ``.dat``, its TOML sidecar and the ground truth.

For ``out/capture.dat`` :func:`simulate_to_file` writes

* ``out/capture.dat`` — plain packed frames, ``H·W/8`` bytes per tick, pixel ``row·W + col`` at
  bit ``p % 8`` of byte ``p // 8`` (least significant bit first), rows stored upside down when
  ``config.flip_vertical`` (the ecosystem's convention; readers flip them back by default);
* ``out/capture.dat.toml`` — the sidecar: ``[stream]`` (geometry, tick rate, CFA after the
  reader's flips, flips), ``[simulation]`` (every :class:`SimConfig` setting; reload it with
  ``SimConfig.load(path, table="simulation")``), ``[scene]`` (what was simulated) and
  ``[ground_truth]`` (file name and ticks);
* ``out/capture.gt.npz`` — a compressed (deflate) ``.npz`` holding ``frames`` (N, H, W, 3)
  **float16** linear RGB in display orientation (not flipped; half precision keeps 11
  significant bits, far below the sensor's noise), ``ticks`` (N,) int64 and ``tick_rate``
  (float64 scalar); frame ``i`` is the clean scene at tick ``ticks[i]`` (every
  ``config.gt_every`` ticks from 0, 50 by default). Read it with :func:`load_ground_truth`.

Sizes: the capture takes ``H·W/8`` bytes per tick, a ground-truth frame at most ``6·H·W`` bytes
before compression, so with the default ``gt_every = 50`` the ground truth is never larger than
the capture (at most 48/50 of it, usually far less after compression). :func:`planned_sizes`
gives both figures; :func:`simulate_to_file` refuses to start when the disk cannot hold them and
reserves the capture's full size up front, so a full disk is reported before any work.

Everything streams: spikes are packed chunk by chunk and ground-truth frames are appended as
they are rendered, so memory stays at one chunk whatever ``n_ticks`` is. Files appear under their
final names only when complete (written under temporary names, then renamed); on any failure
(a full disk included) no temporary and no half-written file is left.
"""

from __future__ import annotations

import io
import os
import zipfile
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np

from spikeview.errors import Cancelled, InputFileError, OutputFileError, ParameterError, SpikeviewError
from spikeview.io.plain import PlainDatWriter
from spikeview.io.sidecar import sidecar_path, write_sidecar
from spikeview.io.source import StreamInfo
from spikeview.sim.config import SimConfig
from spikeview.sim.scenes import Scene
from spikeview.sim.simulator import CancelCheck, ProgressCallback, SpikeSimulator


def ground_truth_path(dat_path: str | Path) -> Path:
    """The ground truth of a spike file: ``capture.dat`` → ``capture.gt.npz``."""
    p = Path(dat_path)
    return p.with_name(p.stem + ".gt.npz")


@dataclass
class SimulationFiles:
    """What :func:`simulate_to_file` wrote.

    Attributes:
        dat: the spike file; sidecar: its TOML sidecar; ground_truth: the ``.gt.npz``.
        info: the stream as a reader should see it (after its flips).
    """

    dat: Path
    sidecar: Path
    ground_truth: Path
    info: StreamInfo


#: dtype of the stored ground-truth frames
GT_DTYPE = np.dtype("<f2")
#: deflate level of the ground truth (1: fast; smooth frames still shrink several times)
GT_COMPRESSLEVEL = 1


def planned_sizes(config: SimConfig, height: int, width: int) -> tuple[int, int]:
    """``(capture_bytes, ground_truth_bytes_at_most)`` of a simulation to file.

    The ground-truth figure is before compression (plus the archive's few hundred bytes), so
    the file is usually smaller.
    """
    n_gt = len(range(0, config.n_ticks, config.gt_every))
    return config.n_ticks * (height * width // 8), n_gt * height * width * 3 * GT_DTYPE.itemsize + 4096


class _GroundTruthWriter:
    """Appends (H, W, 3) frames as float16 to the ``frames`` array of a compressed ``.npz`` without holding them."""

    def __init__(self, fileobj: BinaryIO, n: int, height: int, width: int):
        self._zip = zipfile.ZipFile(fileobj, mode="w", compression=zipfile.ZIP_DEFLATED, allowZip64=True,
                                    compresslevel=GT_COMPRESSLEVEL)
        self._expected = n
        self._written = 0
        self._entry = self._zip.open("frames.npy", mode="w", force_zip64=True)
        np.lib.format.write_array_header_2_0(
            self._entry, {"descr": np.lib.format.dtype_to_descr(GT_DTYPE), "fortran_order": False,
                          "shape": (n, height, width, 3)})

    def append(self, frame: np.ndarray) -> None:
        self._entry.write(np.ascontiguousarray(frame, dtype=GT_DTYPE).tobytes())
        self._written += 1

    def finish(self, ticks: np.ndarray, tick_rate: float) -> None:
        if self._written != self._expected:
            raise RuntimeError(f"ground truth has {self._written} frames, expected {self._expected}")
        self._entry.close()
        for name, arr in (("ticks", np.asarray(ticks, dtype=np.int64)), ("tick_rate", np.asarray(tick_rate, dtype=np.float64))):
            with self._zip.open(f"{name}.npy", mode="w") as f:
                np.lib.format.write_array(f, arr, allow_pickle=False)
        self._zip.close()

    def abort(self) -> None:
        """Drop the archive without finishing it (the caller closes and removes the file)."""
        try:
            self._entry.close()
        except (OSError, ValueError, RuntimeError):  # a full disk fails the entry's last write
            pass
        # forget the file: closing the archive now would only try to write its directory
        self._zip.fp = None


def _temp(path: Path) -> Path:
    return path.with_name(f".{path.name}.tmp{os.getpid()}")


def scene_inputs(scene: Scene | str | Path) -> list[Path]:
    """The files a scene reads (a video, a still, the frames of a sequence), which outputs may not replace."""
    if isinstance(scene, (str, Path)):
        p = Path(scene)
        return [p] if p.is_file() else []
    out: list[Path] = []
    for obj in (scene, getattr(scene, "scene", None), getattr(scene, "base", None)):
        if obj is None:
            continue
        for attr in ("path", "source", "image_path"):
            v = getattr(obj, attr, None)
            if isinstance(v, (str, Path)):
                out.append(Path(v))
        out += [Path(f) for f in getattr(obj, "files", None) or []]
    return out


def simulate_to_file(scene: Scene | str | Path, config: SimConfig, out_path: str | Path, *,
                     progress: ProgressCallback | None = None, cancel: CancelCheck | None = None,
                     overwrite: bool = False, inputs: Iterable[str | Path | None] = (),
                     announce: Callable[[str], None] | None = None) -> SimulationFiles:
    """Simulate ``config.n_ticks`` ticks of ``scene`` into a plain ``.dat``, sidecar and ground truth.

    Args:
        scene: a :class:`Scene` or a path :func:`~spikeview.sim.scenes.open_scene` opens (not
            closed here when you pass a Scene).
        config: the settings (``config.flip_vertical`` decides the row order in the file).
        out_path: the ``.dat`` to write; the sidecar and ground truth go next to it (see the
            module docstring).
        progress: ``progress(done_ticks, total_ticks)`` after each chunk.
        cancel: polled between chunks; returning True removes the partial files and raises
            :class:`~spikeview.errors.Cancelled`.
        overwrite: replace existing output files; when False (the default) an existing file is
            an error, raised before any work.
        inputs: files the run reads (the scene's own files are added); an output may never be
            one of them, even with ``overwrite``.
        announce: called with one sentence stating the sizes before a large write
            (:data:`~spikeview._files.LARGE_WRITE_BYTES` or more); the CLI prints it.

    Returns:
        The :class:`SimulationFiles` written.

    Raises:
        ParameterError: bad settings, a scene shorter than the run, or ``width · height`` not a
            multiple of 8 (plain frames must be whole bytes).
        OutputFileError: the folder is missing or not writable, a file exists and ``overwrite``
            is False, an output is an input, the disk cannot hold the files (checked first), or
            a write failed (the disk filled up): then nothing is left behind.
    """
    from spikeview._files import (LARGE_WRITE_BYTES, RawFile, check_free_space, check_writable, human_bytes,
                                  os_error_sentence)

    out_path = Path(out_path)
    targets = [out_path, sidecar_path(out_path), ground_truth_path(out_path)]
    if not out_path.parent.is_dir():
        raise OutputFileError(f"{out_path.parent}: output folder does not exist; create it or choose another path.")
    protected = [*scene_inputs(scene), *(Path(p) for p in inputs if p)]
    for t in targets:
        check_writable(t, overwrite, protected)
    sim = SpikeSimulator(scene, config)
    h, w = sim.height, sim.width
    if (h * w) % 8:
        if not isinstance(scene, Scene):
            sim.close()
        raise ParameterError(
            f"A plain .dat frame must be whole bytes but {w}x{h} = {w * h} pixels is not a multiple of 8: "
            "set width/height (or crop) so that width·height divides by 8."
        )
    dat_bytes, gt_bytes = planned_sizes(config, h, w)
    try:
        check_free_space(out_path.parent, dat_bytes + gt_bytes,
                         f"{out_path.name} ({human_bytes(dat_bytes)}) and its ground truth (up to {human_bytes(gt_bytes)})")
    except OutputFileError:
        if not isinstance(scene, Scene):
            sim.close()
        raise
    if announce is not None and dat_bytes + gt_bytes >= LARGE_WRITE_BYTES:
        announce(f"writing {out_path.name} ({human_bytes(dat_bytes)}) and {targets[2].name} (up to "
                 f"{human_bytes(gt_bytes)}, one frame every {config.gt_every} ticks; --gt-every changes it)")
    gt_ticks = np.arange(0, config.n_ticks, config.gt_every, dtype=np.int64)
    dat, side, gt_path = targets
    tmp_dat, tmp_gt = _temp(dat), _temp(gt_path)
    gt_writer: _GroundTruthWriter | None = None
    writer: PlainDatWriter | None = None
    fgt: BinaryIO | None = None
    renamed: list[Path] = []
    try:
        writer = PlainDatWriter(tmp_dat, w, h, flip_vertical=config.flip_vertical, cfa=config.cfa_or_none,
                                tick_rate=config.tick_rate, sidecar=False, reserve_frames=config.n_ticks)
        fgt = io.BufferedWriter(RawFile(tmp_gt), buffer_size=1 << 20)
        gt_writer = _GroundTruthWriter(fgt, len(gt_ticks), h, w)
        buf = np.empty((sim.chunk_ticks, h, w), dtype=np.uint8)
        next_gt = 0
        total = config.n_ticks
        while sim.tick < total:
            if cancel is not None and cancel():
                raise Cancelled(f"Simulation cancelled at tick {sim.tick} of {total}.")
            end = min(total, sim.tick + sim.chunk_ticks)
            k = 0
            # run up to each ground-truth tick, then render it: the scene is only ever asked
            # for later times, so videos decode forward without rewinding
            while sim.tick < end:
                if next_gt < len(gt_ticks) and gt_ticks[next_gt] == sim.tick:
                    gt_writer.append(sim.gt_at(sim.tick))
                    next_gt += 1
                stop = end if next_gt >= len(gt_ticks) else min(end, int(gt_ticks[next_gt]))
                n = max(stop, sim.tick + 1) - sim.tick
                sim.run(n, out=buf[k:k + n])
                k += n
            writer.write(buf[:k])
            if progress is not None:
                progress(sim.tick, total)
        gt_writer.finish(gt_ticks, config.tick_rate)
        gt_writer = None
        fgt.flush()
        os.fsync(fgt.fileno())
        fgt.close()
        fgt = None
        writer.close()
        info = writer.info.replace(path=dat)
        from spikeview.transfer import DISPLAY_KEY

        info.extra[DISPLAY_KEY] = "srgb"  # rates in proportion to the scene's linear light (its ground truth is linear)
        tables: dict[str, Any] = {
            "simulation": config.to_dict(),
            "scene": sim.scene.describe(),
            "ground_truth": {"file": gt_path.name, "n_frames": int(len(gt_ticks)), "every_ticks": config.gt_every,
                             "first_tick": 0, "dtype": "float16"},
        }
        os.replace(tmp_dat, dat)
        renamed.append(dat)
        os.replace(tmp_gt, gt_path)
        renamed.append(gt_path)
        # a .dat without its sidecar cannot be read back correctly: on failure nothing stays
        write_sidecar(dat, info, tables)
    except BaseException as e:
        # clean up without letting a second failure (a full disk fails the flush in close()
        # too) hide the first one or leave temporaries behind
        for step in (
            (lambda: gt_writer.abort()) if gt_writer is not None else None,
            (lambda: fgt.close()) if fgt is not None else None,
            (lambda: writer.discard()) if writer is not None else None,
        ):
            if step is not None:
                try:
                    step()
                except (OSError, ValueError, RuntimeError, SpikeviewError):
                    pass
        for tmp in (tmp_dat, tmp_gt, *renamed):
            try:
                tmp.unlink(missing_ok=True)
            except OSError:
                pass
        if isinstance(e, OSError):
            raise OutputFileError(f"{out_path}: could not write the simulation: {os_error_sentence(e)}.") from None
        if isinstance(e, OutputFileError):
            # name the user's files, never the temporaries they were being written to
            msg = str(e)
            for tmp, final in ((tmp_dat, dat), (tmp_gt, gt_path)):
                msg = msg.replace(str(tmp), str(final)).replace(tmp.name, final.name)
            if msg != str(e) or out_path.name not in msg:
                raise OutputFileError(msg if out_path.name in msg else f"{out_path}: {msg}") from None
        raise
    finally:
        if not isinstance(scene, Scene):
            sim.close()
    info.extra = tables
    return SimulationFiles(dat=dat, sidecar=side, ground_truth=gt_path, info=info)


# ---------------------------------------------------------------------------------------------
# reading the ground truth back
# ---------------------------------------------------------------------------------------------
@dataclass
class GroundTruth:
    """Ground-truth frames of a simulated capture.

    Attributes:
        frames: (N, H, W, 3) float32 linear RGB in [0, 1], display orientation (stored as float16).
        ticks: (N,) int64 tick of each frame (increasing).
        tick_rate: ticks per second.
    """

    frames: np.ndarray
    ticks: np.ndarray
    tick_rate: float

    def __len__(self) -> int:
        return len(self.ticks)

    def at(self, tick: int) -> np.ndarray:
        """The frame stored for ``tick``; raises :class:`ParameterError` naming the nearest stored ticks."""
        i = int(np.searchsorted(self.ticks, tick))
        if i < len(self.ticks) and self.ticks[i] == tick:
            return self.frames[i]
        near = sorted({int(self.ticks[j]) for j in (i - 1, i) if 0 <= j < len(self.ticks)})
        raise ParameterError(f"No ground truth at tick {tick}: frames are stored at ticks {near} nearby "
                             f"(every {int(self.ticks[1] - self.ticks[0]) if len(self.ticks) > 1 else '-'} ticks); use one of those.")

    def nearest(self, tick: float) -> tuple[int, np.ndarray]:
        """``(stored_tick, frame)`` of the stored frame closest to ``tick``."""
        i = int(np.argmin(np.abs(self.ticks - tick)))
        return int(self.ticks[i]), self.frames[i]


def load_ground_truth(path: str | Path) -> GroundTruth:
    """Read a ``.gt.npz`` written by :func:`simulate_to_file` (or give the ``.dat`` it belongs to).

    Raises:
        InputFileError: missing file, or not a ground-truth file.
    """
    p = Path(path)
    if p.suffix.lower() != ".npz":
        p = ground_truth_path(p)
    if not p.is_file():
        raise InputFileError(f"{p}: ground-truth file not found; it is written next to the .dat by simulate_to_file.")
    try:
        with np.load(p, allow_pickle=False) as z:
            if "frames" not in z or "ticks" not in z:
                raise InputFileError(f"{p}: holds {', '.join(z.files) or 'nothing'}, not 'frames' and 'ticks'; "
                                     "point to a .gt.npz written by the simulator.")
            frames = z["frames"]
            ticks = z["ticks"].astype(np.int64)
            tick_rate = float(z["tick_rate"]) if "tick_rate" in z else 20_000.0
    except (OSError, ValueError, zipfile.BadZipFile) as e:
        raise InputFileError(f"{p}: not a readable .npz ({e}); re-run the simulation.") from None
    if frames.ndim != 4 or frames.shape[-1] != 3 or frames.shape[0] != ticks.shape[0]:
        raise InputFileError(f"{p}: frames {frames.shape} and ticks {ticks.shape} do not match; re-run the simulation.")
    return GroundTruth(frames=frames.astype(np.float32, copy=False), ticks=ticks, tick_rate=tick_rate)


def ground_truth_reader(dat_path: str | Path, shape: tuple[int, int], tolerance: int
                        ) -> Callable[[int], np.ndarray | None] | None:
    """``ground_truth(tick)``: the clean linear frame stored nearest ``tick`` in the ``.gt.npz`` beside ``dat_path``
    (loaded on first use), or ``None`` when no frame is stored within ``tolerance`` ticks or it is not ``shape``
    (``(H, W)``); ``None`` instead of a reader when there is no ground-truth file (a damaged one reads as none)."""
    from spikeview.errors import SpikeviewError

    gt_file = ground_truth_path(dat_path)
    if not gt_file.is_file():
        return None
    cache: dict[str, Any] = {}

    def gt(tick: int) -> np.ndarray | None:
        if "gt" not in cache:
            try:
                cache["gt"] = load_ground_truth(gt_file)
            except SpikeviewError:
                cache["gt"] = None
        g = cache["gt"]
        if g is None or not len(g):
            return None
        stored, frame = g.nearest(tick)
        if abs(stored - tick) > tolerance or frame.shape[:2] != tuple(shape):
            return None
        return np.asarray(frame, dtype=np.float32)

    return gt
