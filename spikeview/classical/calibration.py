"""Camera calibration: a profile measured once from a dark and/or a flat capture, applied to every capture of the camera.

A spike camera's photosite ``p`` fires at ``r_p = (k_p · s_c · I + d_p) / θ_p`` spikes per tick (under saturation):
``s_c`` the channel's spectral response (the colour cast), ``k_p`` the photo-response non-uniformity, ``θ_p`` the
threshold (fixed-pattern spread), ``d_p`` the dark current (hot pixels have a large one). A **dark** capture (lens
capped) measures the dark rate ``D_p = d_p / θ_p``; a **flat** capture (a uniform white or gray target, out of
focus, not saturated) measures ``F_p = (k_p · s_c · I_f + d_p) / θ_p``. The profile holds

* ``dark``: ``D_p`` (spikes per tick; zeros without a dark capture);
* ``gain``: the flat field ``G_p = (F_p − D_p) / mean_c(F − D)`` (mean 1 over the photosites of each channel; ones
  without a flat capture);
* ``hot``: the hot (and dead) photosites: a dark rate more than :data:`HOT_SIGMA` robust σ above the median, or a
  flat gain outside ``[1/4, 4]``;
* ``colour_response``: ``mean_c(F − D)`` per channel R, G, B: the sensor's response to a neutral target, whose
  inverse is the white balance ``--white-balance profile``;
* the captures' fingerprints and the statistics measured.

**The correction** (:meth:`CameraProfile.correct`) maps a mosaicked rate frame ``r`` (TFP ``count / Δτ``, TFI
``1 / interval``) to ``(r − D) / G``, each hot photosite replaced by the mean of its non-hot neighbours of the same
channel. It is not clipped at 0: a dark photosite's rate minus its dark rate is noise around 0, and clipping it would
brighten the dark parts of the frame by a gray raw offset that the white balance turns into a colour (exports clip as
always; the guided observation clips to [0, 1] as every observation). It is applied to the rates in one place per consumer of rates: the classical frames
(:func:`spikeview.classical.reconstruct.reconstruct_frame`), the guided observation
(:func:`spikeview.guided.window.observe_window`) and the sequence's statistics (white balance, white point), all
through :func:`correct_rates`. The profile travels with the source (``source.info.camera``, set by :func:`attach`),
so every front end that opens a capture with ``--camera`` sees the same corrected rates.

The file is a TOML (``[camera]`` geometry, ``[colour]``, ``[stats]``, ``[captures.*]``) and, for the per-photosite
maps, an ``.npz`` beside it, named in ``[camera] arrays`` with its SHA-256 (a profile whose maps were replaced or
damaged is refused).
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from spikeview.cfa import CHANNEL_NAMES, cfa_to_str, channel_map, parse_cfa
from spikeview.errors import InputFileError, ParameterError

PROFILE_VERSION = 1
#: a photosite whose dark rate is this many robust σ above the median is hot
HOT_SIGMA = 6.0
#: a flat gain outside [1/GAIN_LIMIT, GAIN_LIMIT] marks a dead or stuck photosite
GAIN_LIMIT = 4.0
#: the flat capture must fire below this rate on average in every channel (a saturated pixel has no gain)
FLAT_MAX_RATE = 0.9
#: ... and above this one (too few spikes: the gain would be noise)
FLAT_MIN_RATE = 0.02
#: bytes of a capture hashed for its fingerprint (its start; the size is recorded too)
FINGERPRINT_BYTES = 16 << 20


def _channels(cfa: str | None, h: int, w: int) -> np.ndarray:
    return np.zeros((h, w), dtype=np.int8) if cfa is None else channel_map(cfa, h, w)


@dataclass
class CameraProfile:
    """A camera's dark, flat and colour calibration (see the module docstring).

    Attributes:
        width, height, cfa, flip_vertical, flip_horizontal: the geometry the captures were read with (the maps are
            in that orientation); a capture read otherwise is refused.
        dark: ``(H, W)`` float32 dark rate, spikes per tick.
        gain: ``(H, W)`` float32 flat-field gain, mean 1 per channel.
        hot: ``(H, W)`` bool hot or dead photosites.
        colour_response: ``(3,)`` mean flat response per channel R, G, B in spikes per tick (``None``: no flat capture
            or monochrome).
        captures: fingerprints of the captures (``{"dark": {...}, "flat": {...}}``).
        stats: what was measured (plain numbers).
        path: the TOML file (``None`` before it is saved).
    """

    width: int
    height: int
    cfa: str | None
    dark: np.ndarray
    gain: np.ndarray
    hot: np.ndarray
    colour_response: np.ndarray | None = None
    flip_vertical: bool = False
    flip_horizontal: bool = False
    captures: dict[str, dict[str, Any]] = field(default_factory=dict)
    stats: dict[str, Any] = field(default_factory=dict)
    path: Path | None = None
    _fill: tuple[np.ndarray, ...] | None = field(default=None, repr=False, compare=False)

    def __post_init__(self) -> None:
        self.cfa = parse_cfa(self.cfa)
        where = str(self.path) if self.path is not None else "camera profile"
        shape = (int(self.height), int(self.width))
        if min(shape) < 1:
            raise ParameterError(f"{where}: width and height must be positive, got {self.width}x{self.height}; "
                                 "make the profile again with spikeview calibrate.")
        for name in ("dark", "gain", "hot"):
            arr = np.asarray(getattr(self, name))
            if arr.shape != shape:
                raise ParameterError(f"{where}: its {name} map is {arr.shape[::-1] if arr.ndim == 2 else arr.shape} "
                                     f"but the profile says {self.width}x{self.height}; make the profile again with "
                                     "spikeview calibrate.")
        self.dark = np.asarray(self.dark, dtype=np.float32)
        self.gain = np.asarray(self.gain, dtype=np.float32)
        self.hot = np.asarray(self.hot, dtype=bool)
        if not (np.isfinite(self.dark).all() and (self.dark >= 0).all() and (self.dark <= 1).all()):
            raise ParameterError(f"{where}: its dark map holds values that are not rates in [0, 1] spikes per tick "
                                 "(NaN, negative or above 1); make the profile again with spikeview calibrate.")
        if not (np.isfinite(self.gain).all() and (self.gain > 0).all()):
            raise ParameterError(f"{where}: its gain map holds zero, negative or non-finite gains; make the profile "
                                 "again with spikeview calibrate from a flat capture that is not dark.")
        if self.colour_response is not None:
            c = np.asarray(self.colour_response, dtype=np.float64).reshape(-1)
            if self.cfa is None or c.shape != (3,) or not (np.isfinite(c).all() and (c > 0).all()):
                raise ParameterError(f"{where}: its colour response {c.tolist()} is not three positive rates R, G, B "
                                     "(a Bayer camera's); make the profile again with spikeview calibrate --flat.")
            self.colour_response = c

    # ------------------------------------------------------------------------------ views
    @property
    def name(self) -> str:
        return self.path.name if self.path is not None else "the camera profile"

    def colour_gains(self) -> np.ndarray:
        """The white balance of a neutral target: ``1 / colour_response`` relative to G, float64 ``(3,)``."""
        if self.colour_response is None:
            raise ParameterError(f"{self.name} has no colour response (no flat capture, or a monochrome camera): make it "
                                 "with spikeview calibrate --flat FLAT, or choose another --white-balance.")
        return self.colour_response[1] / self.colour_response

    @property
    def from_capture(self) -> bool:
        """The capture's own defect map (:func:`spikeview.classical.defects.auto_profile`), not a calibration."""
        return self.stats.get("source") == "capture"

    def describe(self) -> str:
        """One line: what the profile corrects."""
        if self.from_capture:
            n = int(self.hot.sum())
            dark = float(self.stats.get("dark_rate_mean", 0.0) or 0.0)
            also = f", its dark rate {dark:.3g} spikes/tick subtracted" if dark > 0 else ""
            return (f"none given; the capture's own {n} hot pixel{'s' if n != 1 else ''} filled from {'their' if n != 1 else 'its'} neighbours"
                    f"{also} (defects below).")
        parts = []
        if self.captures.get("dark"):
            parts.append(f"dark rate {self.stats.get('dark_rate_mean', float(self.dark.mean())):.4g} spikes/tick, "
                         f"{int(self.hot.sum())} hot pixels")
        if self.captures.get("flat"):
            parts.append(f"flat field (gain σ {self.stats.get('gain_std', float(self.gain.std())):.3g})")
        if self.colour_response is not None:
            g = self.colour_gains()
            parts.append(f"colour response (gains R {g[0]:.3g}, G 1, B {g[2]:.3g})")
        return f"camera profile {self.name}: " + ("; ".join(parts) if parts else "no correction") + "."

    # ------------------------------------------------------------------------- the correction
    def _fill_plan(self) -> tuple[np.ndarray, ...]:
        """Hot photosites and their same-channel non-hot neighbours (indices and weights), computed once."""
        if self._fill is None:
            ys, xs = np.nonzero(self.hot)
            step = 1 if self.cfa is None else 2
            ny, nx, ok = [], [], []
            for dy, dx in ((-step, 0), (step, 0), (0, -step), (0, step)):
                y, x = ys + dy, xs + dx
                inside = (y >= 0) & (y < self.height) & (x >= 0) & (x < self.width)
                y, x = np.clip(y, 0, self.height - 1), np.clip(x, 0, self.width - 1)
                ny.append(y)
                nx.append(x)
                ok.append(inside & ~self.hot[y, x])
            w = np.stack(ok, axis=1).astype(np.float32)
            self._fill = (ys, xs, np.stack(ny, axis=1), np.stack(nx, axis=1), w, w.sum(axis=1))
        return self._fill

    def moves_rates(self) -> str | None:
        """What of the correction shifts or scales the rates (``"dark rate"``, ``"flat field"``, both), or ``None``
        (a profile of hot pixels only, such as the capture's own)."""
        parts = [name for name, on in (("dark rate", bool((self.dark != 0).any())),
                                       ("flat field", bool((self.gain != 1).any()))) if on]
        return " and ".join(parts) or None

    def correct(self, rates: np.ndarray) -> np.ndarray:
        """``(r − dark) / gain`` per photosite (not clipped), hot photosites filled from their channel's neighbours.

        Args:
            rates: ``(..., H, W)`` mosaicked rates in spikes per tick (flips applied, the profile's geometry).

        Returns:
            float32 of the same shape (values may be slightly negative where the dark rate exceeds a dark
            window's count, and exceed 1 where a low-gain photosite saturates).
        """
        r = np.asarray(rates)
        if r.shape[-2:] != (self.height, self.width):
            raise ParameterError(f"{self.name} is for {self.width}x{self.height} frames, not "
                                 f"{r.shape[-1]}x{r.shape[-2]}; use the profile of the camera that made the capture.")
        out = (r.astype(np.float32) - self.dark) / self.gain
        ys, xs, ny, nx, w, n = self._fill_plan()
        if ys.size:
            vals = out[..., ny, nx]  # (..., n_hot, 4)
            fill = (vals * w).sum(axis=-1) / np.maximum(n, 1)
            out[..., ys, xs] = np.where(n > 0, fill, 0.0)
        return out

    def check_source(self, info: Any) -> None:
        """Refuse (one sentence) a capture this profile does not describe: another size, CFA or orientation."""
        got = (int(info.width), int(info.height))
        if got != (self.width, self.height):
            raise ParameterError(f"{self.name} was measured on {self.width}x{self.height} captures but this capture is "
                                 f"{got[0]}x{got[1]}; use the profile of the camera that made it (or fix --width/--height).")
        if parse_cfa(info.cfa) != self.cfa:
            raise ParameterError(f"{self.name} was measured with CFA {cfa_to_str(self.cfa)} but this capture is read as "
                                 f"{cfa_to_str(info.cfa)}; read both the same way (--cfa, --flip-vertical).")
        flips = (bool(info.flip_vertical), bool(info.flip_horizontal))
        if flips != (self.flip_vertical, self.flip_horizontal):
            def say(v: bool, h: bool) -> str:
                return ", ".join(n for n, f in (("rows flipped", v), ("columns flipped", h)) if f) or "no flips"
            raise ParameterError(f"{self.name} was measured with {say(self.flip_vertical, self.flip_horizontal)} but "
                                 f"this capture is read with {say(*flips)}; read both the same way "
                                 "(--flip-vertical/--no-flip-vertical).")

    # --------------------------------------------------------------------------------- files
    def save(self, path: str | Path) -> Path:
        """Write ``path`` (TOML) and ``path`` with suffix ``.npz`` (the maps); returns the TOML's path."""
        import io

        from spikeview._files import write_atomic

        path = Path(path)
        arrays = path.with_suffix(".npz")
        buf = io.BytesIO()
        np.savez_compressed(buf, dark=self.dark, gain=self.gain, hot=self.hot)
        blob = buf.getvalue()
        write_atomic(arrays, blob, "the profile's maps", "choose a folder you can write to")
        camera = {"version": PROFILE_VERSION, "width": self.width, "height": self.height, "cfa": cfa_to_str(self.cfa),
                  "flip_vertical": self.flip_vertical, "flip_horizontal": self.flip_horizontal,
                  "arrays": arrays.name, "arrays_sha256": hashlib.sha256(blob).hexdigest()}
        doc: dict[str, Any] = {"camera": camera}
        if self.colour_response is not None:
            doc["colour"] = {"response": [float(v) for v in self.colour_response],
                             "gains": [float(v) for v in self.colour_gains()]}
        doc["stats"] = self.stats
        doc["captures"] = self.captures
        header = ("# spikeview camera profile (spikeview calibrate); use it with --camera on info, reconstruct and export.\n"
                  f"# per-photosite maps (dark rate, flat gain, hot pixels) in {arrays.name}\n")
        self.path = write_atomic(path, header + _toml(doc), "the camera profile", "choose a folder you can write to")
        return self.path

    @classmethod
    def load(cls, path: str | Path) -> "CameraProfile":
        """Read and check a profile; every problem is one sentence naming the file (:class:`ParameterError`)."""
        from spikeview.config import load_toml

        path = Path(path)
        try:
            doc = load_toml(path)
        except InputFileError as e:
            raise ParameterError(f"--camera: {e}") from None
        cam = doc.get("camera")
        if not isinstance(cam, dict) or "width" not in cam or "arrays" not in cam:
            raise ParameterError(f"{path}: not a camera profile (no [camera] table with width, height and arrays); make "
                                 "one with spikeview calibrate.")
        if cam.get("version") != PROFILE_VERSION:
            raise ParameterError(f"{path}: camera profile version {cam.get('version')!r} is not {PROFILE_VERSION}; make "
                                 "it again with this spikeview's calibrate.")
        arrays = path.parent / str(cam["arrays"])
        try:
            blob = arrays.read_bytes()
        except OSError:
            raise ParameterError(f"{path}: its maps file {arrays.name} is missing beside it; keep the .toml and the .npz "
                                 "that spikeview calibrate wrote together.") from None
        if hashlib.sha256(blob).hexdigest() != cam.get("arrays_sha256"):
            raise ParameterError(f"{path}: {arrays.name} is not the maps file this profile was written with (its SHA-256 "
                                 "differs); make the profile again with spikeview calibrate.")
        import io
        import zipfile

        try:
            with np.load(io.BytesIO(blob), allow_pickle=False) as z:
                maps = {k: z[k] for k in ("dark", "gain", "hot")}
        except (OSError, ValueError, KeyError, zipfile.BadZipFile):
            raise ParameterError(f"{path}: {arrays.name} does not hold the dark, gain and hot maps; make the profile "
                                 "again with spikeview calibrate.") from None
        try:
            width, height = int(cam["width"]), int(cam["height"])
            cfa = parse_cfa(cam.get("cfa"))
        except (TypeError, ValueError, ParameterError):
            raise ParameterError(f"{path}: [camera] width, height or cfa is not valid; make the profile again with "
                                 "spikeview calibrate.") from None
        colour = doc.get("colour", {})
        response = colour.get("response") if isinstance(colour, dict) else None
        try:
            response = None if response is None else np.asarray(response, dtype=np.float64)
        except (TypeError, ValueError):
            raise ParameterError(f"{path}: [colour] response is not three numbers R, G, B; make the profile again with "
                                 "spikeview calibrate --flat.") from None
        return cls(width, height, cfa, maps["dark"], maps["gain"], maps["hot"], response,
                   bool(cam.get("flip_vertical", False)), bool(cam.get("flip_horizontal", False)),
                   dict(doc.get("captures", {})), dict(doc.get("stats", {})), path)


def _toml(doc: dict[str, Any]) -> str:
    """Nested plain tables of numbers, strings, booleans and lists as TOML."""
    def value(v: Any) -> str:
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, (int, np.integer)):
            return str(int(v))
        if isinstance(v, (float, np.floating)):
            return repr(float(v)) if math.isfinite(float(v)) else "nan"
        if isinstance(v, (list, tuple)):
            return "[" + ", ".join(value(x) for x in v) + "]"
        s = str(v).replace("\\", "\\\\").replace('"', '\\"')
        return f'"{s}"'

    lines: list[str] = []

    def table(name: str, d: dict[str, Any]) -> None:
        plain = {k: v for k, v in d.items() if not isinstance(v, dict)}
        lines.append(f"\n[{name}]")
        lines.extend(f"{k} = {value(v)}" for k, v in plain.items())
        for k, v in d.items():
            if isinstance(v, dict):
                table(f"{name}.{k}", v)

    for k, v in doc.items():
        table(k, v)
    return "\n".join(lines).lstrip("\n") + "\n"


# ---------------------------------------------------------------------------------- measuring


def fingerprint(source: Any) -> dict[str, Any]:
    """What identifies a capture: its file name, size, SHA-256 of its first :data:`FINGERPRINT_BYTES` bytes, ticks."""
    info = source.info
    out: dict[str, Any] = {"ticks": int(source.n_frames), "format": str(info.format)}
    if info.path is not None:
        p = Path(info.path)
        out["file"] = p.name
        try:
            out["bytes"] = p.stat().st_size
            with open(p, "rb") as f:
                out["sha256_start"] = hashlib.sha256(f.read(FINGERPRINT_BYTES)).hexdigest()
        except OSError:
            pass
    return out


def mean_rates(source: Any, chunk: int = 4096) -> np.ndarray:
    """Mean spikes per tick of every photosite over the whole capture, ``(H, W)`` float64."""
    from spikeview.classical.tfp import window_counts

    total = np.zeros((source.height, source.width), dtype=np.float64)
    for a in range(0, source.n_frames, chunk):
        total += window_counts(source, a, min(a + chunk, source.n_frames))
    return total / max(source.n_frames, 1)


def _robust_sigma(v: np.ndarray) -> float:
    med = float(np.median(v))
    return 1.4826 * float(np.median(np.abs(v - med)))


def measure(dark: Any = None, flat: Any = None) -> CameraProfile:
    """A profile from a dark and/or a flat capture (sources with the same geometry; see the module docstring).

    Raises:
        ParameterError: neither capture, captures of different geometry, or a flat capture too dark or saturated.
    """
    if dark is None and flat is None:
        raise ParameterError("spikeview calibrate needs a dark capture (--dark) and/or a flat capture (--flat).")
    ref = flat if flat is not None else dark
    info = ref.info
    h, w, cfa = int(ref.height), int(ref.width), parse_cfa(ref.cfa)
    if dark is not None and flat is not None:
        a, b = dark.info, flat.info
        if (a.width, a.height, parse_cfa(a.cfa), a.flip_vertical, a.flip_horizontal) != (
                b.width, b.height, parse_cfa(b.cfa), b.flip_vertical, b.flip_horizontal):
            raise ParameterError(f"the dark capture ({a.width}x{a.height}, {cfa_to_str(a.cfa)}) and the flat capture "
                                 f"({b.width}x{b.height}, {cfa_to_str(b.cfa)}) are not read the same way; give both the "
                                 "same geometry flags.")
    ch = _channels(cfa, h, w)
    names = ("Y",) if cfa is None else CHANNEL_NAMES
    stats: dict[str, Any] = {}
    captures: dict[str, dict[str, Any]] = {}
    d = np.zeros((h, w), dtype=np.float64)
    hot = np.zeros((h, w), dtype=bool)
    if dark is not None:
        d = mean_rates(dark)
        med, sig = float(np.median(d)), _robust_sigma(d)
        limit = med + HOT_SIGMA * max(sig, 1.0 / max(dark.n_frames, 1))  # at least one spike's worth of rate
        hot = d > limit
        captures["dark"] = fingerprint(dark)
        stats.update(dark_rate_mean=float(d[~hot].mean()) if (~hot).any() else float(d.mean()),
                     dark_rate_median=med, dark_rate_sigma=sig, hot_limit=float(limit), hot_pixels=int(hot.sum()),
                     hot_rate_mean=float(d[hot].mean()) if hot.any() else 0.0, dark_ticks=int(dark.n_frames))
    gain = np.ones((h, w), dtype=np.float64)
    response = None
    if flat is not None:
        f = mean_rates(flat)
        sig = f - d
        means = []
        for c, name in enumerate(names):
            m = (ch == c) & ~hot
            mc = float(sig[m].mean()) if m.any() else 0.0
            raw = float(f[(ch == c)].mean()) if (ch == c).any() else 0.0
            if raw >= FLAT_MAX_RATE:
                raise ParameterError(f"the flat capture's {name} photosites fire {raw:.2f} spikes per tick on average: "
                                     "it is saturated, so it measures no gain; capture the flat target dimmer.")
            if mc < FLAT_MIN_RATE:
                raise ParameterError(f"the flat capture's {name} photosites fire {mc:.3f} spikes per tick above dark: too "
                                     "dark to measure a gain; capture the flat target brighter (or longer).")
            means.append(mc)
        m_arr = np.asarray(means)
        gain = sig / m_arr[ch]
        bad = ~np.isfinite(gain) | (gain < 1.0 / GAIN_LIMIT) | (gain > GAIN_LIMIT)
        stats.update(dead_pixels=int((bad & ~hot).sum()))
        hot |= bad
        gain[hot] = 1.0
        for c in range(len(names)):  # mean 1 per channel over the good photosites
            m = (ch == c) & ~hot
            if m.any():
                gain[ch == c] /= float(gain[m].mean())
        gain[hot] = 1.0
        if cfa is not None:
            response = m_arr
        captures["flat"] = fingerprint(flat)
        stats.update(flat_rate={n: float(f[ch == c].mean()) for c, n in enumerate(names)},
                     gain_std=float(gain[~hot].std()), flat_ticks=int(flat.n_frames))
        stats["hot_pixels"] = int(hot.sum())
    d_out = np.where(hot, 0.0, d)  # a hot photosite is filled from its neighbours, not dark-subtracted
    return CameraProfile(w, h, cfa, d_out, gain, hot, response, bool(info.flip_vertical), bool(info.flip_horizontal),
                         captures, stats)


# ------------------------------------------------------------------------------- applying it


def attach(source: Any, profile: CameraProfile | str | Path | None) -> Any:
    """``source`` with ``profile`` (or the profile file) as its camera: checked against the capture's geometry, CFA and
    flips (one sentence if it does not match), then carried in ``source.info.camera`` (views of the source keep it)."""
    if profile is None:  # no profile: the capture's own hot photosites (spikeview.classical.defects), when it has any
        auto = capture_profile(source)
        if auto is not None:
            source.info = source.info.replace(camera=auto)
        return source
    if not isinstance(profile, CameraProfile):
        profile = CameraProfile.load(profile)
    profile.check_source(source.info)
    source.info = source.info.replace(camera=profile)
    return source


def attach_own(source: Any) -> Any:
    """``source`` with the capture's own corrections (:func:`capture_profile`) unless it already carries a camera
    profile: how the CLI and the app open a capture without ``--camera`` (the benches open theirs so too)."""
    if camera_of(source) is None:
        attach(source, None)
    return source


def capture_profile(source: Any) -> CameraProfile | None:
    """A profile of the capture's own hot photosites and, for a colour capture whose darkest patches agree in R, G and
    B, its dark rate (:func:`spikeview.classical.defects.find_defects`; uniform, unit gain) for a capture opened
    without a camera profile; ``None`` when it has neither."""
    from spikeview.classical.defects import find_defects

    d = find_defects(source)
    if not d.hot.any() and d.dark <= 0:
        return None
    info = source.info
    h, w = d.hot.shape
    return CameraProfile(w, h, info.cfa, np.full((h, w), d.dark, np.float32), np.ones((h, w), np.float32), d.hot,
                         flip_vertical=bool(info.flip_vertical), flip_horizontal=bool(info.flip_horizontal),
                         stats={"source": "capture", "hot_pixels": int(d.hot.sum()), "ticks": d.ticks,
                                "dark_rate_mean": d.dark})


def camera_of(source: Any) -> CameraProfile | None:
    """The camera profile a source was opened with (``None``: no correction)."""
    info = getattr(source, "info", None)
    return getattr(info, "camera", None)


def correct_rates(source: Any, rates: np.ndarray) -> np.ndarray:
    """``rates`` (``(..., H, W)`` mosaicked spikes per tick of ``source``) corrected by its camera profile, or unchanged
    without one: the one correction the classical frames, the guided observation and the sequence statistics see."""
    cam = camera_of(source)
    return rates if cam is None else cam.correct(rates)


def correct_observation(source: Any, obs: Any) -> Any:
    """A guided :class:`~spikeview.guided.observation.Observation` of ``source`` (and its previous and own windows) with
    its rates corrected in place by :func:`correct_rates` (clipped to [0, 1], as observations are); unchanged without a
    camera profile."""
    cam = camera_of(source)
    if cam is None:
        return obs
    # a dark rate or a flat field moves the rates off the TFP's 1/Δτ grid that the sampler's Q models (hot pixels
    # alone do not: they are filled from their neighbours' counts)
    moved = cam.moves_rates()
    for o in (obs, obs.previous, obs.own):
        if o is not None:
            o.y = np.clip(correct_rates(source, o.y), -1.0 if moved else 0.0, 1.0).astype(np.float32)
            if moved:
                o.corrected = f"the camera profile {cam.name}'s {moved}"
    return obs
