"""The app's session model: plain Python, no Qt.

A :class:`Session` holds everything the desktop app shows or edits — the open stream, the current
tick, the playback state, the marks and ROI, and the named parameters (window Δτ, display levels,
reconstruction, guided and export settings) — and announces every change through simple
:class:`Event` callbacks. Widgets bind to it both ways (a widget calls :meth:`Session.set`; the
model's ``param_changed`` event updates the widget); the tests drive the same object without a
window.

Conventions:

* ticks are readout indices of the stream (50 µs at 20 kHz); ``tick`` is the centre of the window
  ``[a, b)`` every preview reads (see :func:`spikeview.classical.windows.window_range`);
* the reconstruction parameters are views of the recipe (:data:`spikeview.recipe.PARAMS`: name,
  default, range, unit and help come from there); :data:`PARAM_SPECS` adds the app's own settings
  (playback, export destination, preview options). :meth:`Session.recipe` is the session as a
  :class:`~spikeview.recipe.Recipe` (what presets save and the CLI re-runs);
* parameter changes are undoable; a group (one slider drag, one preset load) is one undo step.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from spikeview.errors import ParameterError
from spikeview.config import check_value
from spikeview.recipe import BY_KEY, PARAMS, Param, Recipe

# ------------------------------------------------------------------------------------------ events


class Event:
    """A named list of callbacks: ``connect(fn)``, ``disconnect(fn)``, ``emit(*args)``.

    Callbacks run synchronously, in connection order, on the thread that emits (the GUI thread for
    everything :class:`Session` emits). A callback may disconnect itself while being called.
    """

    def __init__(self, name: str = "") -> None:
        self.name = name
        self._callbacks: list[Callable[..., Any]] = []

    def connect(self, callback: Callable[..., Any]) -> Callable[..., Any]:
        if callback not in self._callbacks:
            self._callbacks.append(callback)
        return callback

    def disconnect(self, callback: Callable[..., Any]) -> None:
        with contextlib.suppress(ValueError):
            self._callbacks.remove(callback)

    def emit(self, *args: Any) -> None:
        for cb in list(self._callbacks):
            cb(*args)

    def __len__(self) -> int:
        return len(self._callbacks)


class SessionEvents:
    """The events of a :class:`Session` (arguments in brackets).

    * ``source_changed()`` — a stream was opened, replaced or re-interpreted (CFA/flip);
    * ``tick_changed(tick)`` — the current centre tick moved;
    * ``param_changed(name, value)`` — one named parameter changed (also on undo/redo);
    * ``playback_changed(playing)`` — play/pause;
    * ``marks_changed(mark_in, mark_out)`` — the marked range changed (``None`` = unset);
    * ``roi_changed(roi)`` — the region of interest ``(x, y, w, h)`` or ``None``;
    * ``undo_changed(can_undo, can_redo)`` — the undo stack changed;
    * ``message(text)`` — a one-line note for the status bar.
    """

    def __init__(self) -> None:
        self.source_changed = Event("source_changed")
        self.tick_changed = Event("tick_changed")
        self.param_changed = Event("param_changed")
        self.playback_changed = Event("playback_changed")
        self.marks_changed = Event("marks_changed")
        self.roi_changed = Event("roi_changed")
        self.undo_changed = Event("undo_changed")
        self.message = Event("message")


# -------------------------------------------------------------------------------------- parameters


@dataclass(frozen=True)
class ParamSpec:
    """Declaration of one named parameter.

    ``kind`` is ``int``, ``float``, ``bool`` or ``str``; numbers must lie in ``[minimum, maximum]``
    and strings among ``choices``. ``undoable=False`` marks navigation-like settings (playback,
    export destination) that are remembered but not put on the undo stack.
    """

    name: str
    kind: type
    default: Any
    label: str
    group: str
    minimum: float | None = None
    maximum: float | None = None
    step: float | None = None
    choices: tuple[str, ...] = ()
    unit: str = ""
    undoable: bool = True
    help: str = ""

    def validate(self, value: Any) -> Any:
        """Return ``value`` converted to ``kind``; raise :class:`ParameterError` (naming the control) if it does not fit."""
        return check_value(self.label, self.kind, value, self.minimum, self.maximum, self.choices, unit=self.unit)


#: the app's group of each recipe parameter (which previews a change makes stale); default: its table
_GROUPS = {"classical.window": "stream", "classical.tfi_half_window": "stream", "classical.eta": "forward",
           "guided.k": "forward", "guided.levels": "forward", "guided.quantise": "forward",
           "guided.temporal_radius": "forward",  # Δτ_eff per photosite: the data term and the pooling map
           "export.black": "display", "export.white": "display", "export.transfer": "display",
           "export.gamma": "display", "run.method": "export"}
#: the app shows an unset boolean (the plan decides) as a three-way choice
TRI_STATE = {None: "auto", True: "on", False: "off"}


def _optional_bool(p: Param) -> bool:
    return p.kind() is bool and p.optional


def _recipe_spec(p: Param) -> ParamSpec:
    """The app control of a recipe parameter (its one home is :data:`spikeview.recipe.PARAMS`)."""
    kind, default, choices = p.kind(), p.default(), p.choices
    if _optional_bool(p):
        kind, default, choices = str, TRI_STATE[default], tuple(TRI_STATE.values())
    elif kind is str and default is None:
        default = ""
    elif kind is float and default is None:
        default = 1.0  # the app shows a number; it sets the sequence's estimate when a capture opens
    lo = p.lo
    if lo is not None and p.lo_open:
        lo = lo + (p.step or 0.01)
    group = _GROUPS.get(p.path, p.table)
    return ParamSpec(p.key, kind, default, p.label, group, lo, p.hi, p.step, choices,
                     unit=p.unit, undoable=group != "export", help=p.help)


def to_recipe_value(name: str, value: Any) -> Any:
    """A control's value as the recipe stores it (``auto`` → ``None``, an empty path → ``None``)."""
    p = BY_KEY[name]
    if _optional_bool(p):
        return {v: k for k, v in TRI_STATE.items()}[value]
    if p.kind() is str and value == "" and p.default() is None:
        return None
    return value


def from_recipe_value(name: str, value: Any) -> Any:
    """A recipe value as its control shows it (inverse of :func:`to_recipe_value`)."""
    p = BY_KEY[name]
    if _optional_bool(p):
        return TRI_STATE[value]
    if value is None and p.kind() is str:
        return ""
    return value


PARAM_SPECS: tuple[ParamSpec, ...] = tuple(_recipe_spec(p) for p in PARAMS if p.key) + (
    # the app's own settings (not part of a recipe)
    ParamSpec("show_pyramid", bool, False, "Residual per pyramid level", "forward", undoable=False),
    # playback (remembered, not undoable)
    ParamSpec("speed", str, "window", "Speed", "playback", choices=("realtime", "slowmo", "window"), undoable=False,
              help="Real time, slow motion ×1/N, or every window in turn."),
    ParamSpec("slowmo", int, 200, "Slow motion N", "playback", 2, 100_000, 1, undoable=False),
    ParamSpec("loop", bool, True, "Loop", "playback", undoable=False),
    # export (remembered, not undoable)
    ParamSpec("export_format", str, "png", "Format", "export", choices=("png", "exr", "mp4"), undoable=False),
    ParamSpec("export_range", str, "frame", "Range", "export", choices=("frame", "marked"), undoable=False),
)

SPECS: dict[str, ParamSpec] = {p.name: p for p in PARAM_SPECS}


def default_params() -> dict[str, Any]:
    """A fresh dict of every parameter's default value."""
    return {p.name: p.default for p in PARAM_SPECS}


# ------------------------------------------------------------------------------------ the source


@dataclass
class OpenedStream:
    """A stream opened in the session, with what the app needs besides the source itself.

    Attributes:
        source: the spike source (flips applied; ``source.cfa`` names what ``read`` returns).
        label: short name for the title bar ("demo capture", a file name).
        path: the file, or ``None`` for the demo and in-memory streams.
        reopen: ``reopen(cfa=..., flip_vertical=...) -> OpenedStream`` re-interprets the same data
            with other settings (``None`` when the stream cannot be re-interpreted).
        ground_truth: ``ground_truth(tick) -> (H, W, 3) float32 in [0, 1]`` for simulated captures.
        open_kwargs: the settings it was opened with (remembered in recent files).
    """

    source: Any
    label: str
    path: Path | None = None
    reopen: Callable[..., OpenedStream] | None = None
    ground_truth: Callable[[int], Any] | None = None
    open_kwargs: dict[str, Any] = field(default_factory=dict)

    @property
    def is_simulated(self) -> bool:
        return self.ground_truth is not None


# ------------------------------------------------------------------------------------------- undo


@dataclass
class UndoEntry:
    """One undo step: ``changes[name] = (old, new)``."""

    label: str
    changes: dict[str, tuple[Any, Any]] = field(default_factory=dict)


class UndoStack:
    """Undo/redo of parameter changes, with groups that merge into one step."""

    def __init__(self, limit: int = 200) -> None:
        self.limit = limit
        self.undo_entries: list[UndoEntry] = []
        self.redo_entries: list[UndoEntry] = []
        self._group: UndoEntry | None = None
        self._depth = 0

    @property
    def can_undo(self) -> bool:
        return bool(self.undo_entries)

    @property
    def can_redo(self) -> bool:
        return bool(self.redo_entries)

    @property
    def in_group(self) -> bool:
        return self._depth > 0

    def begin(self, label: str) -> None:
        if self._depth == 0:
            self._group = UndoEntry(label)
        self._depth += 1

    def end(self) -> bool:
        """Close a group; returns True when the outermost group closed with a real change."""
        if self._depth == 0:
            return False
        self._depth -= 1
        if self._depth > 0:
            return False
        group, self._group = self._group, None
        assert group is not None
        return self._push(group)

    def record(self, name: str, old: Any, new: Any, label: str) -> bool:
        if self._group is not None:
            prev = self._group.changes.get(name)
            self._group.changes[name] = (prev[0] if prev else old, new)
            return False
        return self._push(UndoEntry(label, {name: (old, new)}))

    def _push(self, entry: UndoEntry) -> bool:
        entry.changes = {k: v for k, v in entry.changes.items() if v[0] != v[1]}
        if not entry.changes:
            return False
        self.undo_entries.append(entry)
        del self.undo_entries[: -self.limit]
        self.redo_entries.clear()
        return True

    def clear(self) -> None:
        self.undo_entries.clear()
        self.redo_entries.clear()


# ---------------------------------------------------------------------------------------- session


class Session:
    """Everything the app shows or edits, with change events and undo/redo (see module docstring).

    All mutation happens through methods; read the state through the attributes/properties.
    Setting something to its current value emits nothing.
    """

    def __init__(self, params: Mapping[str, Any] | None = None) -> None:
        self.events = SessionEvents()
        self.params: dict[str, Any] = default_params()
        #: the recipe the controls edit: fields without a control (e.g. ``guided.data_steps``) keep
        #: the values of the last preset loaded, so saving it back changes nothing
        self.base_recipe = Recipe()
        self.undo_stack = UndoStack()
        self.stream: OpenedStream | None = None
        self.tick = 0
        self.playing = False
        self.mark_in: int | None = None
        self.mark_out: int | None = None
        self.roi: tuple[int, int, int, int] | None = None
        #: how far a dark capture's TFI searches at least (:attr:`spikeview.pipeline.SequenceState.tfi_reach`, set with
        #: the capture's white point), ``None`` otherwise: :meth:`tfi_search`
        self.tfi_reach: int | None = None
        self._play_accum = 0.0
        if params:
            self.update_params(params, record=False, strict=False)

    # --- source ----------------------------------------------------------------------------
    @property
    def source(self) -> Any:
        return None if self.stream is None else self.stream.source

    @property
    def n_frames(self) -> int:
        return 0 if self.stream is None else int(self.stream.source.n_frames)

    @property
    def tick_rate(self) -> float:
        return 20_000.0 if self.stream is None else float(self.stream.source.tick_rate)

    def open_stream(self, stream: OpenedStream, keep_position: bool = False) -> None:
        """Make ``stream`` current. Resets tick (unless ``keep_position``), marks and ROI as needed."""
        old = self.stream
        self.stream = stream
        self.playing = False
        self.tfi_reach = None  # the new capture's comes with its white point
        n = int(stream.source.n_frames)
        same_shape = old is not None and (old.source.height, old.source.width) == (stream.source.height, stream.source.width)
        if keep_position:
            self.tick = min(self.tick, max(n - 1, 0))
        else:
            self.tick = min(n // 2, max(n - 1, 0))
            self.mark_in = self.mark_out = None
        if self.mark_out is not None and self.mark_out >= n:
            self.mark_in = self.mark_out = None
        if not (same_shape and keep_position):
            self.roi = None
        # a window longer than the stream cannot be read: shrink it (said in the status bar)
        if n and self.params["window"] > n:
            self._set_param("window", n, record=False)
            self.events.message.emit(f"Window shortened to {n} ticks: the stream holds only {n} ticks.")
        self.events.source_changed.emit()
        self.events.playback_changed.emit(False)
        self.events.tick_changed.emit(self.tick)
        self.events.marks_changed.emit(self.mark_in, self.mark_out)
        self.events.roi_changed.emit(self.roi)

    def reinterpret(self, **settings: Any) -> None:
        """Re-open the current stream with other settings (``cfa=``, ``flip_vertical=``…)."""
        if self.stream is None or self.stream.reopen is None:
            raise ParameterError("This stream cannot be re-interpreted; open the file again with other settings.")
        self.open_stream(self.stream.reopen(**settings), keep_position=True)

    # --- time --------------------------------------------------------------------------------
    def window_range(self, tick: int | None = None) -> tuple[int, int]:
        """The ticks ``[a, b)`` of the current window (centred, shifted inside the stream)."""
        n = self.n_frames
        w = min(int(self.params["window"]), max(n, 1))
        t = self.tick if tick is None else int(tick)
        a = min(max(t - w // 2, 0), max(n - w, 0))
        return a, a + w

    def tfi_search(self) -> int:
        """How far TFI searches around a tick: the TFI half-window setting, or further on a dark capture
        (:func:`spikeview.pipeline.tfi_half_window`: the CLI's rule)."""
        from spikeview.pipeline import SequenceState, tfi_half_window

        return tfi_half_window(int(self.params["tfi_half_window"]), SequenceState(tfi_reach=self.tfi_reach))

    def set_tick(self, tick: int) -> None:
        """Move to ``tick`` (clamped into the stream: scrubbing past the end stops at the end)."""
        n = self.n_frames
        tick = 0 if n == 0 else min(max(int(tick), 0), n - 1)
        if tick != self.tick:
            self.tick = tick
            self.events.tick_changed.emit(tick)

    def step(self, delta: int) -> None:
        self.set_tick(self.tick + int(delta))

    def go_start(self) -> None:
        self.set_tick(self.play_range()[0])

    def go_end(self) -> None:
        self.set_tick(self.play_range()[1])

    def ticks_to_us(self, ticks: float) -> float:
        return float(ticks) * 1e6 / self.tick_rate

    def time_text(self, tick: int | None = None) -> str:
        """``"tick 1234 / 4000 · 61 700 µs"``."""
        t = self.tick if tick is None else tick
        return f"tick {t} / {max(self.n_frames - 1, 0)} · {format_us(self.ticks_to_us(t))}"

    # --- marks, ROI -----------------------------------------------------------------------------
    def set_mark_in(self, tick: int | None = None) -> None:
        t = self.tick if tick is None else int(tick)
        self.mark_in = t
        if self.mark_out is not None and self.mark_out < t:
            self.mark_out = None
        self.events.marks_changed.emit(self.mark_in, self.mark_out)

    def set_mark_out(self, tick: int | None = None) -> None:
        t = self.tick if tick is None else int(tick)
        self.mark_out = t
        if self.mark_in is not None and self.mark_in > t:
            self.mark_in = None
        self.events.marks_changed.emit(self.mark_in, self.mark_out)

    def clear_marks(self) -> None:
        self.mark_in = self.mark_out = None
        self.events.marks_changed.emit(None, None)

    def marked_range(self) -> tuple[int, int]:
        """The marked ticks ``[in, out]`` (inclusive), defaulting to the whole stream."""
        return self.play_range()

    def play_range(self) -> tuple[int, int]:
        """First and last tick (inclusive) that playback visits."""
        last = max(self.n_frames - 1, 0)
        lo = 0 if self.mark_in is None else min(self.mark_in, last)
        hi = last if self.mark_out is None else min(self.mark_out, last)
        return (lo, hi) if lo <= hi else (0, last)

    def set_roi(self, roi: tuple[int, int, int, int] | None) -> None:
        """Set the region of interest ``(x, y, w, h)`` in pixels (clipped to the frame) or ``None``."""
        if roi is not None and self.source is not None:
            x, y, w, h = (round(v) for v in roi)
            W, H = self.source.width, self.source.height
            x0, y0 = min(max(x, 0), W - 1), min(max(y, 0), H - 1)
            x1, y1 = min(max(x + w, x0 + 1), W), min(max(y + h, y0 + 1), H)
            roi = (x0, y0, x1 - x0, y1 - y0)
            if roi == (0, 0, W, H):
                roi = None
        if roi != self.roi:
            self.roi = roi
            self.events.roi_changed.emit(roi)

    # --- playback -------------------------------------------------------------------------------
    def set_playing(self, playing: bool) -> None:
        playing = bool(playing) and self.n_frames > 0
        if playing and self.tick >= self.play_range()[1] and not self.params["loop"]:
            self.set_tick(self.play_range()[0])  # play from the start when parked at the end
        if playing != self.playing:
            self.playing = playing
            self._play_accum = 0.0
            self.events.playback_changed.emit(playing)

    def toggle_playing(self) -> None:
        self.set_playing(not self.playing)

    def ticks_per_second(self) -> float | None:
        """Stream ticks advanced per wall-clock second (``None`` for "every window" mode)."""
        speed = self.params["speed"]
        if speed == "realtime":
            return self.tick_rate
        if speed == "slowmo":
            return self.tick_rate / self.params["slowmo"]
        return None

    def advance(self, elapsed_s: float) -> int:
        """Advance playback by one display frame that took ``elapsed_s`` seconds; returns the new tick.

        Real time and slow motion move by ``elapsed_s × ticks_per_second`` (fractions carry over,
        so slow playback still moves); "every window" moves by one window Δτ per frame, so every
        window is shown. At the end of the play range playback loops or stops.
        """
        if not self.playing or self.n_frames == 0:
            return self.tick
        tps = self.ticks_per_second()
        if tps is None:
            delta = int(self.params["window"])
        else:
            self._play_accum += max(elapsed_s, 0.0) * tps
            delta = int(self._play_accum + 1e-9)  # 10 × 0.3 ticks is 3 ticks, not 2.999…
            self._play_accum = max(self._play_accum - delta, 0.0)
        lo, hi = self.play_range()
        new = self.tick + delta
        if new > hi:
            if self.params["loop"]:
                new = lo
            else:
                new = hi
                self.set_tick(new)
                self.set_playing(False)
                return self.tick
        self.set_tick(max(new, lo))
        return self.tick

    # --- parameters -----------------------------------------------------------------------------
    def get(self, name: str) -> Any:
        return self.params[name]

    # --- the recipe ---------------------------------------------------------------------------
    def recipe(self) -> Recipe:
        """The session's reconstruction settings as a :class:`~spikeview.recipe.Recipe`
        (``[run]`` and ``[stream]`` as last loaded; :func:`spikeview.session.presets.session_recipe`
        fills them from the open stream and the current tick)."""
        # Built once per set of values: building checks every field (≈15 ms), and the window asks for it
        # several times per change on the GUI thread (previews, export panel, guided run; issue 15: 130 ms
        # on opening a file). A Recipe is treated as immutable (changes make copies: ``with_values``).
        key = tuple(repr(self.params[k]) for k in BY_KEY)
        cached = getattr(self, "_recipe_cache", None)
        if cached is not None and cached[0] is self.base_recipe and cached[1] == key:
            return cached[2]
        values = {p.path: to_recipe_value(k, self.params[k]) for k, p in BY_KEY.items()}
        # the two level sliders move independently: white stays just above black (as the display does)
        values["export.white"] = max(float(values["export.white"]), float(values["export.black"]) + 1e-3)
        recipe = self.base_recipe.with_values(values, names={p.path: p.label for p in BY_KEY.values()})
        self._recipe_cache = (self.base_recipe, key, recipe)
        return recipe

    def load_recipe(self, recipe: Recipe, label: str = "Load preset") -> None:
        """Show ``recipe`` in the controls (one undo step) and keep its other fields."""
        values = {k: from_recipe_value(k, recipe.get(p.path)) for k, p in BY_KEY.items()}
        for k, v in values.items():
            values[k] = SPECS[k].validate(v)
        self.update_params(values, label=label)
        self.base_recipe = recipe

    def set(self, name: str, value: Any, record: bool = True) -> None:
        """Set parameter ``name`` (validated; raises :class:`ParameterError` if it does not fit).

        ``record=False`` skips the undo stack (for values restored from settings).
        """
        if name not in SPECS:
            raise ParameterError(f"Unknown parameter {name!r}; known ones: {', '.join(SPECS)}.")
        self._set_param(name, SPECS[name].validate(value), record=record)

    def _set_param(self, name: str, value: Any, record: bool) -> None:
        old = self.params[name]
        if old == value:
            return
        self.params[name] = value
        if record and SPECS[name].undoable and self.undo_stack.record(name, old, value, SPECS[name].label):
            self._undo_changed()
        self.events.param_changed.emit(name, value)

    def update_params(self, values: Mapping[str, Any], record: bool = True, strict: bool = True,
                      label: str = "Load parameters") -> list[str]:
        """Set several parameters as one undo step. Unknown names raise (``strict``) or are skipped.

        Returns the names that were skipped (unknown, or invalid when not ``strict``).
        """
        skipped: list[str] = []
        checked: dict[str, Any] = {}
        for name, value in values.items():
            if name not in SPECS:
                if strict:
                    raise ParameterError(f"Unknown parameter {name!r}; known ones: {', '.join(SPECS)}.")
                skipped.append(name)
                continue
            try:
                checked[name] = SPECS[name].validate(value)
            except ParameterError:
                if strict:
                    raise
                skipped.append(name)
        with self.undo_group(label):
            for name, value in checked.items():
                self._set_param(name, value, record=record)
        return skipped

    @contextlib.contextmanager
    def undo_group(self, label: str) -> Iterator[None]:
        """Merge every parameter change inside the block into one undo step."""
        self.begin_group(label)
        try:
            yield
        finally:
            self.end_group()

    def begin_group(self, label: str) -> None:
        """Start merging changes (a slider press); pair with :meth:`end_group` (the release)."""
        self.undo_stack.begin(label)

    def end_group(self) -> None:
        if self.undo_stack.end():
            self._undo_changed()

    def undo(self) -> bool:
        """Undo the last parameter change (or group); returns False when there is nothing to undo."""
        return self._undo_redo(self.undo_stack.undo_entries, self.undo_stack.redo_entries, 0)

    def redo(self) -> bool:
        return self._undo_redo(self.undo_stack.redo_entries, self.undo_stack.undo_entries, 1)

    def _undo_redo(self, source: list[UndoEntry], target: list[UndoEntry], which: int) -> bool:
        if self.undo_stack.in_group:
            self.undo_stack.end()  # a stray open group (a press without release) closes first
        if not source:
            return False
        entry = source.pop()
        for name, pair in entry.changes.items():
            self._set_param(name, pair[which], record=False)
        target.append(entry)
        self._undo_changed()
        return True

    def undo_text(self) -> tuple[str | None, str | None]:
        """Labels of the next undo and redo steps (``None`` when empty)."""
        u, r = self.undo_stack.undo_entries, self.undo_stack.redo_entries
        return (u[-1].label if u else None, r[-1].label if r else None)

    def _undo_changed(self) -> None:
        self.events.undo_changed.emit(self.undo_stack.can_undo, self.undo_stack.can_redo)


def format_us(us: float) -> str:
    """Microseconds with thin thousands separators: ``61 700 µs`` (ms above 10 s is still µs)."""
    return f"{us:,.0f} µs".replace(",", "\u2009")
