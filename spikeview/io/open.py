"""Opening any spike file as a :class:`~spikeview.io.source.SpikeSource`.

Where each setting comes from, first match wins:

* **format**: the ``format`` argument; the suffix ``.npy``/``.npz`` (→ ``npz``); the sidecar;
  detection: a raw 1000×1000 stream is recognised by its block tags, otherwise the file size is
  matched against the known geometries (plain 1000×1000, plain 400×250, raw 400×250) and the
  given width/height.
* **width/height**: the arguments; the sidecar; the format (raw formats have fixed sizes); the
  array shape (``.npy``/``.npz``); detection by file size as above.
* **cfa, flips, tick rate**: the arguments; the sidecar; the format's defaults (plain and raw
  400×250 files are stored upside down: ``flip_vertical=True``; raw 1000×1000 and arrays: no flip;
  20,000 ticks per second; monochrome).

When the geometry stays ambiguous or unknown, :class:`~spikeview.errors.GeometryError` lists the
``(width, height)`` candidates that fit and the flags to pass. Any detection that was a guess is
stated in ``info.warnings``.
"""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Any

import numpy as np

from spikeview.cfa import parse_cfa
from spikeview.errors import GeometryError, InputFileError, ParameterError
from spikeview.io._base import check_dims, check_tick_rate, open_bytes
from spikeview.io.sidecar import is_sidecar, read_sidecar
from spikeview.io.source import DEFAULT_TICK_RATE, FORMATS, SpikeSource

#: plain-file geometries tried by size detection, as (width, height)
KNOWN_PLAIN_GEOMETRIES: tuple[tuple[int, int], ...] = ((1000, 1000), (400, 250))
#: default vertical flip of each format (plain and raw400 files are stored upside down)
DEFAULT_FLIP_VERTICAL = {"plain": True, "raw400": True, "raw1m": False, "npz": False}
#: aspect ratios (w, h) used to suggest geometries for a plain file of unknown size
_ASPECTS = ((1, 1), (8, 5), (4, 3), (16, 9), (5, 4), (3, 2), (2, 1))


class _Unset:
    def __repr__(self) -> str:
        return "<unset>"


#: marks "not given" for arguments where ``None`` is a meaningful value (``cfa=None`` = monochrome)
UNSET: Any = _Unset()


def open_source(path: str | os.PathLike[str], *, format: str | None = None, width: int | None = None,
                height: int | None = None, cfa: str | None = UNSET, flip_vertical: bool | None = None,
                flip_horizontal: bool | None = None, tick_rate: float | None = None, layout: str | None = None,
                key: str | None = None, tag_check: str | None = None, check_rates: bool | None = None) -> SpikeSource:
    """Open a spike file: sidecar read automatically, explicit arguments override it.

    Args:
        path: a plain ``.dat``, raw 400×250, raw 1000×1000, ``.npy`` or ``.npz`` spike file.
        format: ``plain``, ``raw400``, ``raw1m`` or ``npz`` (also for ``.npy``); default: see the
            module docstring.
        width, height: decoded frame size in pixels.
        cfa: top-left 2×2 after the flips (``"RGGB"`` …), or ``None``/``"none"`` for monochrome.
            Leave unset to take it from the sidecar (monochrome when there is none).
        flip_vertical, flip_horizontal: flips applied after decoding.
        tick_rate: readouts per second (Hz), default 20,000.
        layout: ``"thw"``/``"hwt"`` axis order of ``.npy``/``.npz`` arrays.
        key: the ``.npz`` member that holds the spikes.
        tag_check: raw 1000×1000 only: ``"sequence"`` (default) or ``"lenient"``.
        check_rates: look at the firing rates of plain and raw 400×250 files and add a warning to
            ``info.warnings`` when they suggest a wrong width, CFA or flip (a few hundred ticks
            are counted, 10–400 ms). Default: when the geometry, CFA or flip did not all come from a
            sidecar. A live preview that reopens the file on every change may turn it off.

    Returns:
        A :class:`SpikeSource` (close it, or use it as a context manager). Its ``info.extra`` holds
        the sidecar's free-form tables (``simulation``, ``recording`` …).

    Raises:
        InputFileError: missing file, folder, empty file, unreadable or damaged file, bad sidecar.
        GeometryError: format or geometry could not be determined (``candidates`` lists the
            ``(width, height)`` pairs that would fit).
        ParameterError: an argument has an invalid value (unknown CFA, negative width …).
    """
    path = Path(path)
    _check_path(path)
    side = read_sidecar(path)
    st = side.stream if side is not None else None

    # ---------------------------------------------------------------------------- settings
    if format is not None:
        fmt: str | None = _check_format(format)
    elif path.suffix.lower() in (".npy", ".npz"):
        fmt = "npz"
    elif st is not None:
        fmt = st.format
    else:
        fmt = None
    if width is not None or height is not None:
        check_dims(width if width is not None else 1, height if height is not None else 1)
    w = width if width is not None else (st.width if st is not None else None)
    h = height if height is not None else (st.height if st is not None else None)
    if cfa is not UNSET:
        cfa_v = parse_cfa(cfa)
    else:
        cfa_v = parse_cfa(st.cfa) if st is not None else None
    tr = check_tick_rate(tick_rate) if tick_rate is not None else (st.tick_rate if st is not None else DEFAULT_TICK_RATE)
    if tag_check is not None and fmt not in (None, "raw1m"):
        raise ParameterError(f"tag_check applies only to raw 1000x1000 streams, not to format {fmt!r}; drop it.")
    notes: list[str] = []

    # --------------------------------------------------------------------------- detection
    detected = fmt is None  # a raw 400x250 format found by _detect has passed the plain-layout check already
    if detected:
        fmt, w, h, note = _detect(path, width=w, height=h)
        notes.append(note)
    if layout is not None and fmt != "npz":
        raise ParameterError(f"layout applies only to .npy/.npz arrays, not to format {fmt!r}; drop --layout.")

    fv = flip_vertical if flip_vertical is not None else (st.flip_vertical if st is not None else DEFAULT_FLIP_VERTICAL[fmt])
    fh = flip_horizontal if flip_horizontal is not None else (st.flip_horizontal if st is not None else False)

    # ------------------------------------------------------------------------------ reader
    src: SpikeSource
    if fmt == "plain":
        if w is None or h is None:
            _, w, h, note = _detect(path, width=w, height=h, only="plain")
            notes.append(note)
        from spikeview.io.plain import PlainDatSource

        src = PlainDatSource(path, w, h, flip_vertical=fv, flip_horizontal=fh, cfa=cfa_v, tick_rate=tr)
    elif fmt in ("raw400", "raw1m"):
        from spikeview.io import raw1m, raw400

        fixed = (raw400.RAW400_WIDTH, raw400.RAW400_HEIGHT) if fmt == "raw400" else (raw1m.RAW1M_WIDTH, raw1m.RAW1M_HEIGHT)
        given = (width, height)
        if any(g is not None and g != f for g, f in zip(given, fixed)):
            raise ParameterError(f"{fmt} streams are always {fixed[0]}x{fixed[1]}, but width/height "
                                 f"{width}x{height} were given; drop --width/--height or change --format.")
        if fmt == "raw400":
            src = raw400.Raw400Source(path, flip_vertical=fv, flip_horizontal=fh, cfa=cfa_v, tick_rate=tr,
                                      check_layout=not detected)
        else:
            src = raw1m.Raw1MSource(path, flip_vertical=fv, flip_horizontal=fh, cfa=cfa_v, tick_rate=tr,
                                    tag_check=tag_check or "sequence")
    else:
        from spikeview.io.arrays import NpySource

        src = NpySource(path, layout=layout, width=w, height=h, cfa=cfa_v, tick_rate=tr, flip_vertical=fv,
                        flip_horizontal=fh, key=key)

    src.info.warnings.extend(n for n in notes if n)
    from_user = width is not None or height is not None or cfa is not UNSET or flip_vertical is not None
    if check_rates is None:
        check_rates = st is None or from_user
    if fmt in ("plain", "raw400") and check_rates and src.n_frames > 0:
        # settings that did not come from a sidecar written with the file: say when the rates disagree
        from spikeview.io.geometry import rate_warnings

        src.info.warnings.extend(rate_warnings(src, check_width=fmt == "plain"))
    elif src.cfa is not None and src.width % 2:
        # a sidecar's geometry is trusted (no rate check), but an odd width under a colour filter is a fact of the file
        from spikeview.io.geometry import odd_width_warning

        src.info.warnings.append(odd_width_warning(src.cfa, src.width))
    from spikeview.transfer import DISPLAY_KEY

    if side is not None:
        src.info.extra.update(side.tables)
        src.info.extra.setdefault("sidecar", str(side.path))
        # a sidecar says how its rates map to display; spikeview's own (simulator, recorder) without the key: linear light
        from spikeview.transfer import TRANSFERS

        shown = side.tables.get("display", {}).get("transfer") if isinstance(side.tables.get("display"), dict) else None
        src.info.extra[DISPLAY_KEY] = shown if shown in TRANSFERS else "srgb"
    else:
        src.info.extra[DISPLAY_KEY] = "linear"  # a file of the ecosystem's: its tools show rates linearly
    return src


# --------------------------------------------------------------------------------- helpers
def _check_path(path: Path) -> None:
    if not path.exists():
        raise InputFileError(f"{path}: file not found; check the path.")
    if path.is_dir():
        raise InputFileError(f"{path}: is a folder; point to a spike file (.dat, .npy, .npz) inside it.")
    if is_sidecar(path):
        raise InputFileError(f"{path}: is a sidecar (settings), not spike data; open {path.with_suffix('').name} instead.")
    try:
        size = path.stat().st_size
    except OSError as e:
        raise InputFileError(f"{path}: cannot read the file ({e.strerror or e}); check the path.") from None
    if size == 0:
        raise InputFileError(f"{path}: the file is empty (0 bytes); check that the capture finished writing.")


def _check_format(format: str) -> str:
    fmt = str(format).strip().lower()
    if fmt == "npy":
        fmt = "npz"
    if fmt not in FORMATS:
        raise ParameterError(f"format {format!r} is unknown: use one of {', '.join(FORMATS)}.")
    return fmt


def _detect(path: Path, *, width: int | None, height: int | None,
            only: str | None = None) -> tuple[str, int, int, str]:
    """Format and geometry of a file without suffix or sidecar hints; ``(format, w, h, note)``.

    ``only="plain"``: the format is known to be plain, only the geometry is detected.
    """
    from spikeview.io import raw1m, raw400

    _, buf = open_bytes(path, "spike")
    size = int(buf.size)
    if only is None and width in (None, raw1m.RAW1M_WIDTH) and height in (None, raw1m.RAW1M_HEIGHT) \
            and raw1m.looks_like_raw1m(buf):
        return "raw1m", raw1m.RAW1M_WIDTH, raw1m.RAW1M_HEIGHT, (
            "detected a raw 1000x1000 stream from its block tags; pass --format to be explicit.")
    if only in (None, "plain"):
        from spikeview.io.geometry import not_spike_data

        # with the geometry given, only what a file plainly is (a signature, text) says it is not spikes
        why = not_spike_data(buf, structure=width is None and height is None)
        if why is not None:
            raise InputFileError(f"{path}: not a spike file ({why}); spikeview reads plain packed .dat spike streams "
                                 "(with --width and --height), raw 400x250 and 1000x1000 camera streams (--format raw400, "
                                 "raw1m) and .npy/.npz spike arrays of 0/1 values.")
    del buf
    if only is None and width is not None and height is not None:
        if (width, height) == (raw400.RAW400_WIDTH, raw400.RAW400_HEIGHT) and size % raw400.RAW400_FRAME_BYTES == 0 \
                and size % (width * height // 8) != 0:
            return _raw400_unless_plain(path, "read as a raw 400x250 stream (its size is whole "
                                              "416-bit-row frames); pass --format to be explicit.")
        return "plain", width, height, ""
    cands = [c for c in _size_candidates(size) if only is None or c[0] == only]
    if width is not None or height is not None:
        cands = [c for c in cands if (width is None or c[1] == width) and (height is None or c[2] == height)]
    if len(cands) == 1:
        fmt, w, h = cands[0]
        if fmt == "plain" and width is None and height is None:
            _check_known_size_against_rates(path, w, h, size)
        what = "a raw 400x250 stream" if fmt == "raw400" else f"a plain {w}x{h} file"
        note = (f"no sidecar, read as {what} because its size ({size} bytes) is a whole number "
                f"of such frames; pass --format, --width and --height to be explicit.")
        return _raw400_unless_plain(path, note) if fmt == "raw400" else (fmt, w, h, note)
    if len(cands) > 1:
        listed = "; ".join(f"--format {f} --width {w} --height {h}" for f, w, h in cands)
        geoms = list(dict.fromkeys((w, h) for _, w, h in cands))
        hint = ""
        if width is None and height is None and any(f == "plain" for f, _, _ in cands):
            from spikeview.io.geometry import rank_plain_geometries

            guesses = rank_plain_geometries(path)
            if not guesses or guesses[0].temporal <= 0:  # no scene in the spikes: nothing to add
                pass
            elif guesses[0].size in geoms:  # list the one the spikes agree with first
                best = guesses[0]
                geoms = [best.size, *(g for g in geoms if g != best.size)]
                cands = sorted(cands, key=lambda c: (c[0] != "plain" or (c[1], c[2]) != best.size))
                listed = "; ".join(f"--format {f} --width {w} --height {h}" for f, w, h in cands)
                hint = f" (its spikes point to the first, {best.width}x{best.height} with {best.n_frames} ticks)"
            else:
                # the spikes point elsewhere: offer that first
                best = guesses[0]
                hint = (f", or the size its spikes suggest, --width {best.width} --height {best.height} "
                        f"({best.n_frames} ticks), which is the most likely")
                geoms = [guesses[0].size, *geoms]
        raise GeometryError(f"{path}: its size ({size} bytes) fits several known formats or sizes, so pass one of: "
                            f"{listed}{hint}.", geoms)
    raise _unknown_plain_geometry(path, width, height, size)


def _raw400_unless_plain(path: Path, note: str) -> tuple[str, int, int, str]:
    """A detected raw 400x250 stream, or a plain 400x250 file when its spikes repeat at the plain frame size
    (a plain capture cut to a whole number of raw frames; see :func:`~spikeview.io.raw400.plain_400x250_evidence`)."""
    from spikeview.io import raw400

    _, buf = open_bytes(path, "spike")
    why = raw400.plain_400x250_evidence(buf)
    w, h = raw400.RAW400_WIDTH, raw400.RAW400_HEIGHT
    if why is None:
        return "raw400", w, h, note
    return "plain", w, h, (f"read as a plain {w}x{h} file although its size is whole raw 400x250 frames, as {why}; "
                           "pass --format plain --width 400 --height 250 to be explicit.")


def _size_candidates(size: int) -> list[tuple[str, int, int]]:
    """Known formats whose frame size divides ``size`` exactly, as ``(format, width, height)``."""
    from spikeview.io import raw400

    out = [("plain", w, h) for (w, h) in KNOWN_PLAIN_GEOMETRIES if size % (w * h // 8) == 0]
    if size % raw400.RAW400_FRAME_BYTES == 0:
        out.append(("raw400", raw400.RAW400_WIDTH, raw400.RAW400_HEIGHT))
    return out


def plain_geometry_candidates(size: int, limit: int = 8) -> list[tuple[int, int]]:
    """``(width, height)`` pairs whose plain frames divide a file of ``size`` bytes exactly.

    Known sensor sizes come first, then frames with common aspect ratios (1:1, 8:5, 4:3, 16:9,
    5:4, 3:2, 2:1), largest first, at most ``limit`` in all.
    """
    out: list[tuple[int, int]] = [(w, h) for (w, h) in KNOWN_PLAIN_GEOMETRIES if size % (w * h // 8) == 0]
    if size <= 0:
        return out
    r = math.isqrt(size)
    small = np.arange(1, r + 1, dtype=np.int64)
    small = small[size % small == 0]
    divisors = np.unique(np.concatenate([small, size // small]))
    extra = set()
    for d in divisors[::-1]:  # frame bytes, largest first
        pixels = int(d) * 8
        for a, b in _ASPECTS:
            if pixels % (a * b):
                continue
            k = math.isqrt(pixels // (a * b))
            if k * k * a * b == pixels and min(a * k, b * k) >= 8:
                extra.add((a * k, b * k))
        if len(out) + len(extra) >= 4 * limit:
            break
    rest = sorted(extra - set(out), key=lambda wh: (-(wh[0] * wh[1]), wh))
    return (out + rest)[:limit]


def _ranked_hint(guesses: list) -> str:
    if not guesses:
        return ""
    best, rest = guesses[0], guesses[1:]
    hint = f"; most likely --width {best.width} --height {best.height} ({best.n_frames} ticks)"
    if rest:
        hint += f", then {', '.join(f'{g.width}x{g.height}' for g in rest)}"
    return hint


def _unknown_plain_geometry(path: Path, width: int | None, height: int | None, size: int | None = None) -> GeometryError:
    from spikeview.io.geometry import rank_plain_geometries

    if size is None:
        size = path.stat().st_size
    guesses = [g for g in rank_plain_geometries(path, limit=None)
               if (width is None or g.width == width) and (height is None or g.height == height)][:8]
    cands = [g.size for g in guesses]
    return GeometryError(f"{path}: a plain .dat file has no header and its size ({size} bytes) is not whole frames of "
                         f"a known sensor, so pass --width and --height (and --format if it is not plain)"
                         f"{_ranked_hint(guesses)}.", cands)


def _check_known_size_against_rates(path: Path, w: int, h: int, size: int) -> None:
    """Raise :class:`GeometryError` when a file's size fits a known sensor but its spikes clearly do not."""
    from spikeview.io.geometry import rank_plain_geometries

    guesses = rank_plain_geometries(path, limit=None)
    if not guesses or guesses[0].size == (w, h):
        return
    known = next((g for g in guesses if g.size == (w, h)), None)
    top = guesses[0]
    if known is None or (top.spatial > 0.3 and known.spatial < 0.5 * top.spatial) \
            or known.temporal < 0.5 <= top.temporal:
        raise GeometryError(f"{path}: its size fits {w}x{h} frames of a known sensor but its spikes do not look like "
                            f"them, so pass --width and --height{_ranked_hint(guesses[:8])}.",
                            [g.size for g in guesses[:8]])
