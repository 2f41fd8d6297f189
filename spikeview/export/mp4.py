"""H.264 MP4 video through PyAV, plus the slow-motion arithmetic.

Conventions:
    * Codec libx264, pixel format **yuv420p** (what every player decodes), constant rate factor
      ``crf`` and ``preset`` from the :class:`~spikeview.export.ExportConfig`, ``fps`` frames
      per second, frame ``i`` shown at ``i / fps`` s.
    * Pixels: the fixed display mapping of :mod:`spikeview.export.display` (levels, sRGB curve by
      default, 8 bits), converted to Y'CbCr with **BT.709** coefficients, **limited (TV) range**,
      and tagged so (colour primaries BT.709, transfer sRGB/gamma/linear as configured) so that
      players decode the colours that were meant. Mono frames are written as grey RGB.
    * **Even size**: yuv420p needs an even width and height. An odd size is padded by
      repeating the last row/column once (``even_size="pad"``, the default: nothing is lost, the
      video is one pixel larger) or cropped by one row/column (``"crop"``).
    * Metadata: the container's ``title`` is a one-line summary, its ``comment`` the TOML
      export record (source, method, tick rate, first window, step, ``[params]``,
      ``[export]``, ``slow_motion``).
    * Atomicity: frames are encoded into a hidden temporary file that is renamed on close. On
      **cancel** (``close(allow_partial=True)``) the encoder is flushed and the frames already
      written become a valid, shorter video; with no frame written no file is left. On an
      **error** (``abort()``) the temporary is deleted.
"""

from __future__ import annotations

import contextlib
from fractions import Fraction
from typing import Any

import numpy as np

from spikeview.errors import OutputFileError, ParameterError
from spikeview.export.atomic import AtomicFile
from spikeview.export.base import Exporter
from spikeview.export.display import to_display


def slow_motion_factor(tick_rate: float, step_ticks: float, fps: float) -> float:
    """How much slower than real time a video plays.

    One output frame every ``step_ticks`` ticks covers ``step_ticks / tick_rate`` seconds of
    capture and is shown for ``1 / fps`` seconds, so the factor is
    ``tick_rate / (step_ticks · fps)``. A 20 kHz capture with one frame per 10 ticks played at
    30 fps is ``20000 / (10 · 30) = 66.7``× slow motion; a factor below 1 is a time-lapse.

    Args:
        tick_rate: readouts per second (Hz), > 0.
        step_ticks: ticks between consecutive output frames, > 0.
        fps: playback frames per second, > 0.

    Returns:
        The slow-motion factor (playback time / capture time).
    """
    for name, value in (("tick_rate", tick_rate), ("step_ticks", step_ticks), ("fps", fps)):
        if not (np.isfinite(value) and value > 0):
            raise ParameterError(f"slow motion: '{name}' = {value!r}; pass a positive number.")
    return float(tick_rate) / (float(step_ticks) * float(fps))


def _short(x: float) -> str:
    return f"{x:.0f}" if x >= 1000 else f"{x:.3g}"


def _duration(seconds: float) -> str:
    if seconds >= 1:
        return f"{_short(seconds)} s"
    if seconds >= 1e-3:
        return f"{_short(seconds * 1e3)} ms"
    return f"{_short(seconds * 1e6)} µs"


def describe_slow_motion(factor: float) -> str:
    """A human string for a slow-motion factor.

    Examples:
        >>> describe_slow_motion(20000 / (10 * 30))
        '66.7× slow motion (1 s of video shows 15 ms of capture)'
        >>> describe_slow_motion(0.5)
        '2× time-lapse (1 s of video shows 2 s of capture)'
    """
    if not (np.isfinite(factor) and factor > 0):
        raise ParameterError(f"slow motion factor {factor!r} must be a positive number.")
    shows = f"1 s of video shows {_duration(1.0 / factor)} of capture"
    if abs(factor - 1.0) < 5e-4:
        return f"real time ({shows})"
    if factor > 1:
        return f"{_short(factor)}× slow motion ({shows})"
    return f"{_short(1.0 / factor)}× time-lapse ({shows})"


def fps_fraction(fps: float) -> Fraction:
    """``fps`` as an exact-enough fraction for the container (29.97 → 2997/100, 30 → 30)."""
    return Fraction(fps).limit_denominator(1001 * 1000)


def even_frame(pixels: np.ndarray, mode: str) -> np.ndarray:
    """Make an ``(H, W, 3)`` image's height and width even by padding (``"pad"``) or cropping (``"crop"``).

    Padding repeats the last row/column; cropping drops it.
    """
    h, w = pixels.shape[:2]
    dh, dw = h % 2, w % 2
    if not (dh or dw):
        return pixels
    if mode == "pad":
        return np.pad(pixels, ((0, dh), (0, dw), (0, 0)), mode="edge")
    return pixels[: h - dh, : w - dw]


class Mp4Exporter(Exporter):
    """An H.264/yuv420p MP4 (see module docstring)."""

    format = "mp4"

    def _open(self) -> None:
        import av
        from av.video.reformatter import ColorPrimaries, ColorRange, Colorspace, ColorTrc

        h, w = self.frame_shape[:2]
        if self.config.even_size == "pad":
            self.video_size = (w + w % 2, h + h % 2)
        else:
            self.video_size = (w - w % 2, h - h % 2)
            if min(self.video_size) < 2:
                raise ParameterError(
                    f"{self.path}: a {w}×{h} frame is too small to crop to an even size; use even_size='pad'."
                )
        trc = {"srgb": ColorTrc.IEC61966_2_1, "linear": ColorTrc.LINEAR}.get(self.config.curve())
        if trc is None:  # pure gamma: only 2.2 and 2.8 have tags, other exponents stay unspecified
            trc = {2.2: ColorTrc.GAMMA22, 2.8: ColorTrc.GAMMA28}.get(round(self.config.gamma, 3), ColorTrc.UNSPECIFIED)
        self._colour = {
            "dst_colorspace": Colorspace.ITU709,
            "dst_color_range": ColorRange.MPEG,
            "dst_color_trc": trc,
            "dst_color_primaries": ColorPrimaries.BT709,
        }
        self._file = AtomicFile(self.path)
        try:
            self._container = av.open(str(self._file.tmp), mode="w", format="mp4", options={"movflags": "+faststart"})
        except OSError as e:
            self._file.discard()
            raise OutputFileError(f"{self.path}: could not create the video file ({e}); check the folder.") from None
        try:
            rate = fps_fraction(self.config.fps)
            stream = self._container.add_stream("libx264", rate=rate)
            stream.width, stream.height = self.video_size
            stream.pix_fmt = "yuv420p"
            stream.options = {"crf": str(self.config.crf), "preset": self.config.preset}
            cc = stream.codec_context
            cc.time_base = 1 / rate
            cc.colorspace = int(Colorspace.ITU709)
            cc.color_range = int(ColorRange.MPEG)
            cc.color_trc = int(trc)
            cc.color_primaries = int(ColorPrimaries.BT709)
            record = self.export_record()
            m = self.metadata
            if m.step_ticks is not None:
                factor = slow_motion_factor(m.tick_rate, m.step_ticks, self.config.fps)
                record["slow_motion"] = factor
                record["slow_motion_text"] = describe_slow_motion(factor)
                record["params"] = record.pop("params")
                record["export"] = record.pop("export")
            import tomli_w

            # the title describes the whole video, so not the first frame's window
            title = self.describe({k: v for k, v in record.items() if k not in ("window", "centre_tick")})
            if "slow_motion_text" in record:
                title += f", {record['slow_motion_text']}"
            self._container.metadata["title"] = title
            self._container.metadata["comment"] = tomli_w.dumps(record)
        except av.codec.codec.UnknownCodecError:
            self._container.close()
            self._file.discard()
            raise OutputFileError(
                f"{self.path}: this PyAV build has no libx264 encoder; install the 'av' wheel from PyPI."
            ) from None
        except av.error.FFmpegError as e:
            self._container.close()
            self._file.discard()
            raise OutputFileError(f"{self.path}: the H.264 encoder could not start ({e}).") from None
        except BaseException:
            self._container.close()
            self._file.discard()
            raise
        self._stream = stream

    def _write(self, frame: np.ndarray, index: int, record: dict[str, Any]) -> None:
        import av

        pixels = to_display(frame, self.config, 8)
        if self.mono:
            pixels = np.repeat(pixels[:, :, None], 3, axis=2)
        pixels = np.ascontiguousarray(even_frame(pixels, self.config.even_size))
        vf = av.VideoFrame.from_ndarray(pixels, format="rgb24").reformat(format="yuv420p", **self._colour)
        vf.pts = index
        try:
            for packet in self._stream.encode(vf):
                self._container.mux(packet)
        except (av.error.FFmpegError, OSError) as e:
            raise self._error(f"encoding frame {index} failed", e) from None

    def _finish(self) -> None:
        import av

        try:
            for packet in self._stream.encode(None):
                self._container.mux(packet)
            self._container.close()
        except (av.error.FFmpegError, OSError) as e:
            raise self._error("finishing the video failed", e) from None
        self._file.commit()
        self.paths.append(self.path)

    def _error(self, what: str, e: BaseException) -> OutputFileError:
        """One sentence for a failed write: a full disk said as such, never the temporary's name."""
        from spikeview._files import is_disk_full, os_error_sentence

        if is_disk_full(e):
            return OutputFileError(f"{self.path}: {what}: {os_error_sentence(e)}.")
        detail = getattr(e, "strerror", None) or str(e)
        detail = str(detail).replace(str(self._file.tmp), str(self.path)).rstrip(".")
        return OutputFileError(f"{self.path}: {what} ({detail}); check the folder and free disk space.")

    def _discard(self) -> None:
        # the file is being thrown away: errors while closing it do not matter
        with contextlib.suppress(Exception):
            self._container.close()
        self._file.discard()
