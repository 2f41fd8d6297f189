"""Scenes: what the simulated sensor looks at, as linear RGB over continuous time.

A :class:`Scene` answers ``frame_at(t)`` with an ``(H, W, 3)`` float32 array of *linear* RGB in
``[0, 1]`` for a time ``t`` in **seconds**. Internally every scene is a sequence of *key frames*
plus a blend rule: :meth:`Scene.key_at` names the two key frames around ``t`` and the weight of the
second, and ``frame_at(t) = (1 − w)·key_a + w·key_b``. The simulator uses the same decomposition
so that what it integrates is exactly what :meth:`frame_at` (the ground truth) returns, and so it
converts each key frame to a mosaic only once.

Kinds of scene:

* :class:`ImageSequenceScene` — a folder, glob pattern or list of image files at an input frame
  rate, linearly blended between neighbouring frames.
* :class:`VideoScene` — any video PyAV decodes; the frame rate comes from the stream.
* :class:`MotionScene` — a still image under synthetic pan / zoom / rotation, with optional
  rotating :class:`Fan` overlays, rendered at the exact tick time (or at ``render_rate`` key
  frames per second, blended in between).
* :class:`ArrayScene` and :class:`StaticScene` — frames already in memory.
* :class:`ResizedScene` — a crop and/or resize of another scene (what ``SimConfig.crop``,
  ``width`` and ``height`` build).

Images become linear RGB in :mod:`spikeview.sim.images` (sRGB decoding, image files, sequences).
"""

from __future__ import annotations

import fnmatch
import glob
import math
from abc import ABC, abstractmethod
from collections import OrderedDict
from collections.abc import Hashable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from spikeview.errors import InputFileError, ParameterError
from spikeview.sim.images import IMAGE_EXTENSIONS, image_size, list_image_files, read_image, to_linear_rgb

Key = Hashable
#: frames of at least this many pixels are warped by several threads
PARALLEL_MIN_PIXELS = 1 << 18


# ---------------------------------------------------------------------------------------------
# base class
# ---------------------------------------------------------------------------------------------
class Scene(ABC):
    """Linear RGB intensity over time; see the module docstring.

    Attributes:
        height, width: frame size in pixels.
        duration_s: length in seconds (``None``: unbounded, e.g. a still image in motion). Valid
            times are ``0 ≤ t ≤ duration_s``; the last key frame is held until ``duration_s``.
    """

    height: int
    width: int
    duration_s: float | None = None
    #: how many rendered key frames to keep
    cache_size: int = 4

    def __init__(self) -> None:
        self._cache: OrderedDict[Key, np.ndarray] = OrderedDict()

    # --- what subclasses implement --------------------------------------------------------
    @abstractmethod
    def key_at(self, t: float) -> tuple[Key, Key, float]:
        """Key frames around time ``t`` (seconds) and the blend weight ``w`` of the second, in [0, 1]."""

    @abstractmethod
    def _render(self, key: Key) -> np.ndarray:
        """The key frame named ``key``: (H, W, 3) float32 linear RGB in [0, 1]."""

    def describe(self) -> dict[str, Any]:
        """TOML-ready description of the scene (for sidecars)."""
        return {"kind": type(self).__name__, "height": self.height, "width": self.width}

    # --- shared ---------------------------------------------------------------------------
    @property
    def size(self) -> tuple[int, int]:
        """``(height, width)``."""
        return (self.height, self.width)

    def key_frame(self, key: Key) -> np.ndarray:
        """The (cached) key frame named ``key``, (H, W, 3) float32, read-only."""
        frame = self._cache.get(key)
        if frame is not None:
            self._cache.move_to_end(key)
            return frame
        frame = np.ascontiguousarray(self._render(key), dtype=np.float32)
        frame.setflags(write=False)
        self._cache[key] = frame
        while len(self._cache) > max(2, self.cache_size):
            self._cache.popitem(last=False)
        return frame

    def check_time(self, t: float) -> float:
        """Validate a time in seconds; raises :class:`ParameterError` outside ``[0, duration_s]``."""
        t = float(t)
        if not math.isfinite(t) or t < 0 or (self.duration_s is not None and t > self.duration_s * (1 + 1e-12)):
            end = "∞" if self.duration_s is None else f"{self.duration_s:g}"
            raise ParameterError(f"Time {t:g} s is outside the scene, which spans [0, {end}] s: choose a time inside it.")
        return t

    def frame_at(self, t: float) -> np.ndarray:
        """Linear RGB at time ``t`` (seconds): a new (H, W, 3) float32 array in [0, 1]."""
        ka, kb, w = self.key_at(self.check_time(t))
        a = self.key_frame(ka)
        if w == 0.0 or ka == kb:
            return a.copy()
        b = self.key_frame(kb)
        return ((1.0 - w) * a + w * b).astype(np.float32)

    def close(self) -> None:
        """Release files. Safe to call twice."""
        self._cache.clear()

    def __enter__(self) -> "Scene":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class _KeyframeScene(Scene):
    """Key frames ``0 … n−1`` at ``i / fps`` seconds, blended linearly; the last one is held."""

    fps: float
    n_frames: int

    def _setup_timing(self, n_frames: int, fps: float, name: str) -> None:
        if not (math.isfinite(fps) and fps > 0):
            raise ParameterError(f"Frame rate {fps!r} of {name} is invalid: give a positive number of frames per second.")
        self.fps = float(fps)
        self.n_frames = int(n_frames)
        self.duration_s = self.n_frames / self.fps

    def key_at(self, t: float) -> tuple[Key, Key, float]:
        x = t * self.fps
        i = int(math.floor(x))
        if i >= self.n_frames - 1:
            return self.n_frames - 1, self.n_frames - 1, 0.0
        return i, i + 1, float(x - i)


# ---------------------------------------------------------------------------------------------
# in-memory scenes
# ---------------------------------------------------------------------------------------------
class ArrayScene(_KeyframeScene):
    """Frames held in memory, ``(N, H, W, 3)`` (or ``(N, H, W)`` grey), at ``fps`` frames per second."""

    def __init__(self, frames: np.ndarray, fps: float, srgb: bool | None = None):
        super().__init__()
        frames = np.asarray(frames)
        if frames.ndim not in (3, 4) or frames.shape[0] < 1:
            raise ParameterError(f"ArrayScene needs frames of shape (N, H, W, 3) or (N, H, W), got {frames.shape}.")
        self._frames = [to_linear_rgb(f, srgb=srgb, name=f"frame {i}") for i, f in enumerate(frames)]
        self.height, self.width = self._frames[0].shape[:2]
        self._setup_timing(len(self._frames), fps, "the frame array")

    def _render(self, key: Key) -> np.ndarray:
        return self._frames[int(key)]  # type: ignore[call-overload]

    def describe(self) -> dict[str, Any]:
        return {**super().describe(), "fps": self.fps, "n_frames": self.n_frames}


class StaticScene(Scene):
    """One image, unchanged forever (unbounded duration)."""

    def __init__(self, image: np.ndarray, srgb: bool | None = None):
        super().__init__()
        self._image = to_linear_rgb(image, srgb=srgb, name="static image")
        self.height, self.width = self._image.shape[:2]

    def key_at(self, t: float) -> tuple[Key, Key, float]:
        return 0, 0, 0.0

    def _render(self, key: Key) -> np.ndarray:
        return self._image


# ---------------------------------------------------------------------------------------------
# image sequences
# ---------------------------------------------------------------------------------------------
class ImageSequenceScene(_KeyframeScene):
    """Image files shown at ``fps`` frames per second, blended linearly between neighbours.

    Frame ``i`` is at ``i / fps`` seconds. Files are read lazily (a few are cached), so long
    sequences of large frames do not fill memory. Every file must have the size of the first.

    Args:
        files: folder, glob pattern or list of files (see :func:`list_image_files`).
        fps: input frame rate in frames per second.
        srgb: see :func:`read_image`.

    Raises:
        InputFileError: missing/unreadable files, an empty folder, or files of different sizes.
    """

    def __init__(self, files: str | Path | Sequence[str | Path], fps: float, srgb: bool | None = None):
        super().__init__()
        self.files = list_image_files(files)
        self.srgb = srgb
        self.height, self.width = image_size(self.files[0])
        for f in self.files[1:]:
            hw = image_size(f)
            if hw != (self.height, self.width):
                raise InputFileError(
                    f"{f}: image is {hw[1]}x{hw[0]} but {self.files[0].name} is {self.width}x{self.height}; "
                    "all frames of a sequence must have the same size (resize them or remove the odd one)."
                )
        self._setup_timing(len(self.files), fps, f"the image sequence {self.files[0].parent}")

    def _render(self, key: Key) -> np.ndarray:
        frame = read_image(self.files[int(key)], srgb=self.srgb)  # type: ignore[call-overload]
        if frame.shape[:2] != (self.height, self.width):
            raise InputFileError(f"{self.files[int(key)]}: image changed size while reading; re-export the sequence.")  # type: ignore[call-overload]
        return frame

    def describe(self) -> dict[str, Any]:
        return {**super().describe(), "fps": self.fps, "n_frames": self.n_frames,
                "first_file": str(self.files[0]), "last_file": str(self.files[-1])}


# ---------------------------------------------------------------------------------------------
# video
# ---------------------------------------------------------------------------------------------
class VideoScene(_KeyframeScene):
    """A video decoded by PyAV, blended linearly between frames.

    Frame ``i`` is at ``i / fps`` seconds with ``fps`` the stream's average rate (constant frame
    rate is assumed; pass ``fps`` to override). Frames are decoded forward on demand and a few are
    cached; asking for an earlier frame than the decoder's position re-opens the file (the
    simulator only moves forward). Pixels are converted to RGB by FFmpeg and decoded as sRGB.

    Args:
        path: the video file.
        fps: override the stream's frame rate (frames per second).
        srgb: decode the sRGB transfer function (default True, as for almost every video).

    Raises:
        InputFileError: missing file, no video stream, or undecodable data.
    """

    def __init__(self, path: str | Path, fps: float | None = None, srgb: bool = True):
        super().__init__()
        self.path = Path(path)
        self.srgb = srgb
        if not self.path.is_file():
            raise InputFileError(f"{self.path}: video file not found; check the path.")
        container = self._open()
        try:
            stream = container.streams.video[0]
            rate = fps if fps is not None else (stream.average_rate or stream.guessed_rate or stream.base_rate)
            if rate is None:
                raise InputFileError(f"{self.path}: the video stream has no frame rate; pass fps explicitly.")
            n = stream.frames
            if not n:
                n = sum(1 for p in container.demux(stream) if p.size)
            self.height, self.width = stream.codec_context.height, stream.codec_context.width
        finally:
            container.close()
        if n < 1:
            raise InputFileError(f"{self.path}: the video stream holds no frames; check the file.")
        self._setup_timing(n, float(rate), str(self.path))
        self._container: Any = None
        self._frames: Any = None
        self._next_index = 0

    def _open(self) -> Any:
        import av

        try:
            container = av.open(str(self.path))
        except (av.error.FFmpegError, OSError) as e:
            why = getattr(e, "strerror", None) or str(e)
            raise InputFileError(f"{self.path}: not a readable video ({why}); convert it to MP4 (H.264) or a folder of "
                                 "PNGs.") from None
        if not container.streams.video:
            container.close()
            raise InputFileError(f"{self.path}: the file holds no video stream; give a video file.")
        return container

    def _rewind(self) -> None:
        self.close()
        self._container = self._open()
        stream = self._container.streams.video[0]
        stream.thread_type = "AUTO"
        self._frames = self._container.decode(stream)
        self._next_index = 0

    def _render(self, key: Key) -> np.ndarray:
        import av

        index = int(key)  # type: ignore[call-overload]
        if self._frames is None or index < self._next_index:
            self._rewind()
        frame = None
        try:
            while self._next_index <= index:
                frame = next(self._frames)
                self._next_index += 1
        except StopIteration:
            raise InputFileError(
                f"{self.path}: the video ended at frame {self._next_index} although it declares {self.n_frames}; re-encode it."
            ) from None
        except av.error.FFmpegError as e:
            raise InputFileError(f"{self.path}: frame {self._next_index} could not be decoded ({e}); re-encode the video.") from None
        assert frame is not None
        rgb = frame.to_ndarray(format="rgb24")
        if rgb.shape[:2] != (self.height, self.width):
            raise InputFileError(f"{self.path}: frame {index} changes size mid-stream; re-encode the video at one size.")
        return to_linear_rgb(rgb, srgb=self.srgb, name=f"{self.path} frame {index}")

    def close(self) -> None:
        super().close()
        if self._container is not None:
            self._container.close()
        self._container = None
        self._frames = None
        self._next_index = 0

    def describe(self) -> dict[str, Any]:
        return {**super().describe(), "path": str(self.path), "fps": self.fps, "n_frames": self.n_frames}


# ---------------------------------------------------------------------------------------------
# synthetic motion
# ---------------------------------------------------------------------------------------------
@dataclass
class Fan:
    """A fan in front of the scene (fixed on screen), drawn anti-aliased.

    Attributes:
        center: ``(x, y)`` of the hub in output pixels; ``None`` for the frame centre.
        radius: blade tip radius in output pixels; ``None`` for 0.3 × the frame's smaller side.
        rev_per_s: revolutions per second; positive turns clockwise on screen.
        n_blades: number of blades.
        blade_fraction: fraction of the disc the blades cover (0–1).
        colours: blade colours as linear RGB triples, cycled over the blades; blades shade
            darker towards the hub.
        hub_radius: hub radius in pixels; ``hub_colour`` its linear RGB.
        phase_deg: blade angle at t = 0, degrees clockwise from the +x axis.
    """

    center: tuple[float, float] | None = None
    radius: float | None = None
    rev_per_s: float = 5.0
    n_blades: int = 3
    blade_fraction: float = 0.45
    colours: tuple[tuple[float, float, float], ...] = ((0.8, 0.05, 0.03), (0.05, 0.55, 0.08), (0.04, 0.1, 0.85))
    hub_radius: float = 0.0
    hub_colour: tuple[float, float, float] = (0.25, 0.25, 0.25)
    phase_deg: float = 0.0

    def __post_init__(self) -> None:
        if not ((self.radius is None or self.radius > 0) and self.n_blades >= 1 and 0 < self.blade_fraction <= 1
                and len(self.colours) >= 1 and math.isfinite(self.rev_per_s)):
            raise ParameterError(
                f"Fan(radius={self.radius}, n_blades={self.n_blades}, blade_fraction={self.blade_fraction}, "
                f"rev_per_s={self.rev_per_s}) is invalid: use a positive radius, at least one blade, a blade fraction "
                "in (0, 1] and a finite speed."
            )

    def phase_at(self, t: float) -> float:
        """Blade angle at time ``t`` (s) in radians, clockwise on screen."""
        return math.radians(self.phase_deg) + 2.0 * math.pi * self.rev_per_s * t

    def geometry(self, height: int, width: int) -> tuple[float, float, float]:
        """``(cx, cy, radius)`` in a ``height × width`` frame (filling in the defaults)."""
        cx, cy = self.center if self.center is not None else ((width - 1) / 2.0, (height - 1) / 2.0)
        radius = self.radius if self.radius is not None else 0.3 * min(height, width)
        return float(cx), float(cy), float(radius)

    def draw(self, frame: np.ndarray, t: float) -> None:
        """Draw the fan at time ``t`` (seconds) over ``frame`` (H, W, 3) float32, in place."""
        from spikeview.sim import _kernels

        cx, cy, radius = self.geometry(frame.shape[0], frame.shape[1])
        colours = np.array([self.colours[k % len(self.colours)] for k in range(self.n_blades)], dtype=np.float32)
        _kernels.draw_fan(frame, cx, cy, radius, float(self.hub_radius), int(self.n_blades), float(self.blade_fraction),
                          self.phase_at(t), colours, np.asarray(self.hub_colour, dtype=np.float32))

    def describe(self) -> dict[str, Any]:
        d: dict[str, Any] = {"rev_per_s": self.rev_per_s, "n_blades": self.n_blades, "blade_fraction": self.blade_fraction,
                             "hub_radius": self.hub_radius, "phase_deg": self.phase_deg}
        if self.center is not None:
            d["center"] = list(self.center)
        if self.radius is not None:
            d["radius"] = self.radius
        return d


class MotionScene(Scene):
    """A still image under a synthetic camera motion, with optional rotating fans in front.

    At time ``t`` the content is scaled by ``zoom ** t`` and turned by ``rotation · t`` degrees
    (clockwise on screen) about the output centre, then moved by ``pan · t`` pixels; borders
    are mirrored, so any motion stays covered. Sampling is bilinear.

    Rendering happens at the exact time asked (``render_rate=None``), or at ``render_rate`` key
    frames per second blended linearly in between — cheaper for long runs, and the blend is
    indistinguishable while the motion between key frames stays well below a pixel.

    Args:
        image: the still — a file path, or an array (integer arrays are sRGB, float arrays linear;
            see ``srgb``).
        size: output ``(height, width)``; default: the image's size.
        pan: content velocity ``(vx, vy)`` in output pixels per second (+x right, +y down).
        zoom: scale factor per second (1.1 grows the content by 10 % each second; 1 = none).
        rotation: degrees per second, clockwise on screen.
        fans: fans drawn over the moving image (fixed on screen).
        center: point of the image ``(x, y)``, in image pixels, shown at the output centre at
            t = 0; default the image centre.
        scale: output pixels per image pixel at t = 0; default the smallest scale at which the
            image covers the output. The image is resampled once (anti-aliased) at this scale.
        render_rate: key frames per second, or ``None`` to render every time exactly.
        srgb: see :func:`to_linear_rgb`.
    """

    def __init__(self, image: np.ndarray | str | Path, size: tuple[int, int] | None = None, *,
                 pan: tuple[float, float] = (0.0, 0.0), zoom: float = 1.0, rotation: float = 0.0,
                 fans: Sequence[Fan] = (), center: tuple[float, float] | None = None, scale: float | None = None,
                 render_rate: float | None = None, srgb: bool | None = None):
        super().__init__()
        if isinstance(image, (str, Path)):
            self.source_path: str | None = str(image)
            src = read_image(image, srgb=srgb)
        else:
            self.source_path = None
            src = to_linear_rgb(image, srgb=srgb, name="motion scene image")
        h0, w0 = src.shape[:2]
        self.height, self.width = (int(size[0]), int(size[1])) if size is not None else (h0, w0)
        if self.height < 1 or self.width < 1:
            raise ParameterError(f"MotionScene size {size} is invalid: give a positive (height, width).")
        if not (math.isfinite(zoom) and zoom > 0):
            raise ParameterError(f"MotionScene zoom {zoom!r} is invalid: give a positive factor per second (1 = no zoom).")
        if render_rate is not None and not (math.isfinite(render_rate) and render_rate > 0):
            raise ParameterError(f"MotionScene render_rate {render_rate!r} is invalid: give key frames per second or None.")
        self.scale = float(scale) if scale is not None else max(self.height / h0, self.width / w0)
        if not (math.isfinite(self.scale) and self.scale > 0):
            raise ParameterError(f"MotionScene scale {scale!r} is invalid: give output pixels per image pixel (> 0).")
        if abs(self.scale - 1.0) > 1e-9:
            from skimage.transform import resize

            hs, ws = max(1, round(h0 * self.scale)), max(1, round(w0 * self.scale))
            src = resize(src, (hs, ws), order=1, anti_aliasing=self.scale < 1, preserve_range=True).astype(np.float32)
            # use the realised scale so that centre coordinates stay exact
            self._sx, self._sy = ws / w0, hs / h0
        else:
            self._sx = self._sy = 1.0
        self._src = np.ascontiguousarray(src, dtype=np.float32)
        cx, cy = center if center is not None else ((w0 - 1) / 2.0, (h0 - 1) / 2.0)
        self._src_center = ((cx + 0.5) * self._sx - 0.5, (cy + 0.5) * self._sy - 0.5)
        self.center = (float(cx), float(cy))
        self.pan = (float(pan[0]), float(pan[1]))
        self.zoom = float(zoom)
        self.rotation = float(rotation)
        self.fans = list(fans)
        self.render_rate = None if render_rate is None else float(render_rate)
        self.duration_s = None

    def key_at(self, t: float) -> tuple[Key, Key, float]:
        if self.render_rate is None:
            return ("t", t), ("t", t), 0.0
        x = t * self.render_rate
        i = int(math.floor(x))
        w = float(x - i)
        return i, i + 1, w

    def _time_of(self, key: Key) -> float:
        if isinstance(key, tuple):
            return float(key[1])
        return int(key) / self.render_rate  # type: ignore[operator,call-overload]

    def _render(self, key: Key) -> np.ndarray:
        return self.render(self._time_of(key))

    def render(self, t: float) -> np.ndarray:
        """Render the exact frame at ``t`` seconds (no key-frame blending): (H, W, 3) float32."""
        from spikeview.sim import _kernels

        z = self.zoom ** t
        th = math.radians(self.rotation * t)
        c, s = math.cos(th), math.sin(th)
        ox = (self.width - 1) / 2.0 + self.pan[0] * t
        oy = (self.height - 1) / 2.0 + self.pan[1] * t
        # output p = o + z·R(θ)·(src − c_src)  ⇒  src = c_src + R(−θ)·(p − o)/z, R(θ) = [[c, −s], [s, c]]
        m00, m01, m10, m11 = c / z, s / z, -s / z, c / z
        tx = self._src_center[0] - (m00 * ox + m01 * oy)
        ty = self._src_center[1] - (m10 * ox + m11 * oy)
        out = np.empty((self.height, self.width, 3), dtype=np.float32)
        threads = _kernels.default_threads() if self.height * self.width >= PARALLEL_MIN_PIXELS else 1
        _kernels.run_rows(_kernels.warp_affine, self.height, threads, self._src, out, m00, m01, m10, m11, tx, ty)
        for fan in self.fans:
            fan.draw(out, t)
        np.clip(out, 0.0, 1.0, out=out)
        return out

    def describe(self) -> dict[str, Any]:
        d: dict[str, Any] = {**super().describe(), "pan": list(self.pan), "zoom": self.zoom, "rotation": self.rotation,
                             "center": list(self.center), "scale": self.scale, "fans": [f.describe() for f in self.fans]}
        if self.source_path:
            d["image"] = self.source_path
        if self.render_rate is not None:
            d["render_rate"] = self.render_rate
        return d


# ---------------------------------------------------------------------------------------------
# crop / resize
# ---------------------------------------------------------------------------------------------
class ResizedScene(Scene):
    """A crop and/or resize of another scene, with the same timing and key frames.

    Args:
        scene: the scene to transform (closed with this one).
        crop: ``(top, left, height, width)`` in the scene's pixels, or ``None``.
        size: output ``(height, width)``, or ``None`` for the crop's size. Resizing is bilinear,
            anti-aliased when shrinking.
    """

    def __init__(self, scene: Scene, crop: Sequence[int] | None = None, size: tuple[int, int] | None = None):
        super().__init__()
        self.inner = scene
        if crop is not None:
            top, left, h, w = (int(v) for v in crop)
            if top < 0 or left < 0 or h < 1 or w < 1 or top + h > scene.height or left + w > scene.width:
                raise ParameterError(
                    f"Crop [top={top}, left={left}, height={h}, width={w}] does not fit the {scene.width}x{scene.height} scene: "
                    "choose a crop inside it."
                )
            self.crop: tuple[int, int, int, int] | None = (top, left, h, w)
        else:
            self.crop = None
            h, w = scene.height, scene.width
        self.height, self.width = (int(size[0]), int(size[1])) if size is not None else (h, w)
        self.duration_s = scene.duration_s
        self.cache_size = scene.cache_size

    def key_at(self, t: float) -> tuple[Key, Key, float]:
        return self.inner.key_at(t)

    def _render(self, key: Key) -> np.ndarray:
        frame = self.inner.key_frame(key)
        if self.crop is not None:
            top, left, h, w = self.crop
            frame = frame[top:top + h, left:left + w]
        if frame.shape[:2] != (self.height, self.width):
            from skimage.transform import resize

            shrink = frame.shape[0] > self.height or frame.shape[1] > self.width
            frame = resize(frame, (self.height, self.width), order=1, anti_aliasing=shrink, preserve_range=True)
        return np.clip(frame, 0.0, 1.0).astype(np.float32)

    def close(self) -> None:
        super().close()
        self.inner.close()

    def describe(self) -> dict[str, Any]:
        d = {**self.inner.describe()}
        if self.crop is not None:
            d["crop"] = list(self.crop)
        d["height"], d["width"] = self.height, self.width
        return d


def open_scene(path: str | Path, fps: float | None = None, srgb: bool | None = None) -> Scene:
    """Open a scene from a path: a video file, an image-sequence folder or glob, or one image.

    Args:
        path: video (anything PyAV opens), folder of images, glob pattern, or a single image (a
            static scene).
        fps: frame rate of an image sequence (required for sequences); overrides a video's rate.
        srgb: see :func:`to_linear_rgb` (videos default to sRGB).

    Raises:
        InputFileError: nothing at ``path`` or an unreadable file.
        ParameterError: an image sequence without ``fps``.
    """
    p = Path(path)
    spec = str(path)
    if p.is_dir() or glob.has_magic(spec):
        if fps is None:
            raise ParameterError(f"{path}: an image sequence needs its frame rate; pass fps (frames per second).")
        return ImageSequenceScene(path, fps=fps, srgb=srgb)
    if not p.exists():
        raise InputFileError(f"{p}: no such file or folder; check the path of the scene.")
    if any(fnmatch.fnmatch(p.name.lower(), f"*{ext}") for ext in IMAGE_EXTENSIONS):
        return StaticScene(read_image(p, srgb=srgb))
    return VideoScene(p, fps=fps, srgb=True if srgb is None else srgb)
