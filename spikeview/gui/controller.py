"""The glue between the session model and the background workers (Qt, but no widgets).

:class:`Controller` listens to the :class:`~spikeview.session.model.Session`'s events, decides which
previews are stale, submits jobs (:mod:`spikeview.session.jobs`) to the workers
(:mod:`spikeview.gui.workers`), drops stale results by job id and hands fresh ones to the views
through Qt signals. It also drives playback with a timer.

Workers:

* ``preview`` — stream frames, firing rates (throttled), the sequence's colour cast, the
  degradation chain; newest-wins per channel, frames first;
* ``tfi`` — the TFI pane (costly at full size: ±32 ticks per pixel), on its own thread so it never
  holds up the raw/TFP frames, throttled during playback like the rates;
* ``guided`` — the guided sampler; owns the prior model (loaded once, kept in the worker's state);
  parameter changes restart it after a debounce;
* ``export`` — one export at a time, with progress and cancel;
* ``compare`` — TFP and TFI of the window scored against the ground truth (the canvas's comparison and the
  Compare panel), only while shown and paused, after a short debounce.

Playback is back-pressured: the next frame is requested only when the previous one has been
shown, so a slow machine drops frames (real-time mode skips ticks) instead of queueing them, and
the window never waits for a computation.
"""

from __future__ import annotations

import gc
import os
import time
from collections import deque
from pathlib import Path
from typing import Any

import numpy as np
from PySide6 import QtCore

from spikeview import memory
from spikeview.session import jobs
from spikeview.session.model import SPECS, Session
from spikeview.gui.workers import Worker

#: parameter groups whose change makes the stream previews stale
_FRAME_GROUPS = {"stream", "display", "classical"}
#: rates are recomputed at most this often during playback (ms); paused changes are immediate
RATES_INTERVAL_MS = 250
#: the TFI pane is recomputed at most this often during playback (ms)
TFI_INTERVAL_MS = 200
#: guided parameter changes restart a running job after this quiet time (ms): a slider still being dragged waits;
#: 200 ms (was 400) is half of what a knob change on a 256² ROI took before its run started (bench_roi_knob.py)
GUIDED_DEBOUNCE_MS = 200
#: the comparison's scores are recomputed after this quiet time (ms) when the tick, ROI or a parameter changes
COMPARE_DEBOUNCE_MS = 300
#: playback timer period (ms): the display asks for a frame at most this often
PLAY_INTERVAL_MS = 10
#: the display rate playback never exceeds: a screen shows at most 60 frames a second, and painting
#: faster only takes the GUI thread from everything else (issue 10: 144 ms stalls while playing)
MAX_DISPLAY_FPS = 60
#: OS priority (Linux nice value) of the preview, TFI and export worker threads; the GUI thread keeps 0
WORKER_NICE = 5


def _guided_then_release(req: jobs.GuidedRequest, ctx: Any) -> jobs.GuidedResult:
    """The guided job, then the heap memory its passes freed given back to the OS, in the worker thread (only where
    glibc's heap reuse is on, i.e. after an NNPACK pass: :mod:`spikeview.memory`). The app lives long: without it
    RSS grew 1113 → 1272 MB over three 1000² float32-fast runs (peak 1381 MB; with it 1150 MB, and 1142 MB without
    the reuse); ``malloc_trim`` took 34–44 ms, and the runs 5.8 s against 7.5 s without the reuse."""
    try:
        return jobs.guided_job(req, ctx)
    finally:
        memory.release_free_memory()


#: parameters the sequence's white point depends on (Y·α/η over the window): changing one re-estimates it
EXPOSURE_PARAMS = frozenset({"eta", "window", "colour_cast", "white_balance"})

class Controller(QtCore.QObject):
    """Session → jobs → views (see module docstring)."""

    frames_ready = QtCore.Signal(object)  # core.StreamFrames
    tfi_ready = QtCore.Signal(int, object, object)  # tick, uint8 image, full (H, W)
    rates_ready = QtCore.Signal(object)  # core.RatesResult
    alpha_history = QtCore.Signal(object)  # (ticks, alphas (N, C)) sorted by tick
    degradation_ready = QtCore.Signal(object)  # jobs.DegradationView
    redisplayed = QtCore.Signal(object)  # {key: (data, uint8 image)}: the canvas's results at new display levels
    guided_update = QtCore.Signal(object)  # jobs.GuidedUpdate
    guided_done = QtCore.Signal(object)  # jobs.GuidedResult
    guided_state = QtCore.Signal(str, str)  # state ("running", "done", "cancelled", "failed", "idle"), message
    export_progress = QtCore.Signal(int, int)
    export_done = QtCore.Signal(object)  # list[Path]
    export_state = QtCore.Signal(str, str)  # "running" / "done" / "cancelled" / "failed", message
    error = QtCore.Signal(str)  # a sentence for the user (status bar or dialog)
    fps_changed = QtCore.Signal(float)
    alpha_ready = QtCore.Signal(object)
    white_balance_said = QtCore.Signal(str, object)  # the CLI's line (which white balance, why; "" without), the gains α
    guided_started = QtCore.Signal(int, object)  # run, the ROI it runs on (None: the whole frame)
    compare_ready = QtCore.Signal(object)  # jobs.CompareView

    def __init__(self, session: Session, parent: QtCore.QObject | None = None):
        super().__init__(parent)
        self.session = session
        # Every worker runs at a lower OS priority (nice 5) than the GUI thread: on a loaded machine they
        # otherwise took the cores from it and the window froze for 100+ ms (benchmarks/bench_gui.py --stall).
        self.preview = Worker("spikeview-preview", priority=("frames", "redisplay", "degradation", "rates", "alpha"), parent=self,
                              nice=WORKER_NICE)
        # the sampler uses every core, as the CLI does, at a lower OS priority than the window: its torch
        # threads are started by the worker thread and inherit its nice value, so the GUI thread takes a
        # core whenever it has work (benchmarks/bench_ui_stalls.py; one thread had made a 1000×1000 run 2× slower)
        self.guided = Worker("spikeview-guided", parent=self, nice=WORKER_NICE, torch_threads=os.cpu_count() or 1)
        self.exporter = Worker("spikeview-export", parent=self, nice=WORKER_NICE)
        self.tfi = Worker("spikeview-tfi", parent=self, nice=WORKER_NICE)
        # the comparison's scores (seconds on a large frame) on a thread of their own: the TFI pane never waits on them
        self.scorer = Worker("spikeview-compare", parent=self, nice=WORKER_NICE)
        for w in (self.preview, self.guided, self.exporter, self.tfi, self.scorer):
            w.finished.connect(self._on_finished)
            w.failed.connect(self._on_failed)
            w.cancelled.connect(self._on_cancelled)
            w.progress.connect(self._on_progress)
        self.alpha: np.ndarray | None = None
        self.alpha_note: str | None = None
        # "pooling": the guided panel's pooling map is shown (it comes with the degradation job's plan)
        # "compare": the classical methods are scored against the ground truth (the canvas or the Compare panel asks)
        self.enabled = {"tfi": True, "rates": True, "degradation": True, "pooling": False, "compare": False}
        self.display_factor = 1  # stream images are downsampled by this for the screen
        self.errors: list[str] = []  # every error shown, for tests and the log
        self.last_frames = None
        self.guided_result: jobs.GuidedResult | None = None
        self.guided_run = 0
        self.guided_live = False
        self._guided_key: tuple[Any, ...] | None = None
        self._frames_dirty = False
        self._alpha_hist: dict[int, np.ndarray] = {}
        self._shown_times: deque[float] = deque(maxlen=120)
        self._last_advance = time.perf_counter()
        self._last_rates = 0.0
        self._heap_settled_after_model = False

        self.play_timer = QtCore.QTimer(self)
        self.play_timer.setInterval(PLAY_INTERVAL_MS)
        self.play_timer.timeout.connect(self._play_tick)
        self.rates_timer = QtCore.QTimer(self, singleShot=True)
        self.rates_timer.timeout.connect(self._submit_rates)
        self.tfi_timer = QtCore.QTimer(self, singleShot=True)
        self.tfi_timer.timeout.connect(self._submit_tfi)
        self._last_tfi = 0.0
        self.guided_timer = QtCore.QTimer(self, singleShot=True, interval=GUIDED_DEBOUNCE_MS)
        self.guided_timer.timeout.connect(self._guided_debounced)
        self.compare_timer = QtCore.QTimer(self, singleShot=True, interval=COMPARE_DEBOUNCE_MS)
        self.compare_timer.timeout.connect(self.submit_compare)

        ev = session.events
        ev.source_changed.connect(self._on_source)
        ev.tick_changed.connect(self._on_tick)
        ev.param_changed.connect(self._on_param)
        ev.roi_changed.connect(self._on_roi)
        ev.playback_changed.connect(self._on_playback)

    # ------------------------------------------------------------------------------ lifecycle
    def shutdown(self) -> None:
        """Stop playback and every worker (called when the window closes)."""
        self.play_timer.stop()
        self.rates_timer.stop()
        self.tfi_timer.stop()
        self.guided_timer.stop()
        self.compare_timer.stop()
        ev = self.session.events
        for e, cb in ((ev.source_changed, self._on_source), (ev.tick_changed, self._on_tick), (ev.param_changed, self._on_param),
                      (ev.roi_changed, self._on_roi), (ev.playback_changed, self._on_playback)):
            e.disconnect(cb)
        for w in (self.preview, self.guided, self.exporter, self.tfi, self.scorer):
            w.stop()
        gc.unfreeze()  # let the interpreter's final cleanup see everything again

    def set_display_factor(self, factor: int) -> None:
        """Downsample the stream images by ``factor`` (the views ask when their zoom changes)."""
        factor = max(1, int(factor))
        if factor != self.display_factor:
            self.display_factor = factor
            if not self.session.playing:
                self.request_frames()

    def set_enabled(self, what: str, on: bool) -> None:
        """Skip work for hidden views (``"tfi"``, ``"rates"``, ``"degradation"``, ``"pooling"``)."""
        changed = self.enabled.get(what) != on
        self.enabled[what] = on
        if changed and on:
            {"tfi": self.request_tfi, "rates": self.request_rates, "degradation": self.request_degradation,
             "pooling": self.request_degradation, "compare": self.request_compare}[what]()

    # ------------------------------------------------------------------------------ memory
    @staticmethod
    def settle_heap(collect: bool = True) -> None:
        """Move everything alive now out of reach of the cyclic garbage collector.

        A full collection walks every object; with torch, numba and pyqtgraph loaded that is
        millions and takes 100–300 ms, and it runs in whichever thread happens to allocate, with
        the interpreter lock held — a frozen window in the middle of playback or a guided run.
        Freezing the long-lived objects (the modules, the loaded prior, the open stream) after
        they are created keeps later collections short. Called after a stream opens (with a
        collection first, a moment the user is waiting anyway) and after the guided worker has
        loaded its model (no collection).
        """
        if collect:
            gc.collect()
        gc.freeze()

    # ------------------------------------------------------------------------------ session events
    def _on_source(self) -> None:
        QtCore.QTimer.singleShot(0, self.settle_heap)
        self.guided.cancel("guided")
        self.guided_result = None
        self._guided_key = None
        self.alpha, self.alpha_note = None, None
        self.capture_white: float | None = None  # the sequence's white point (Edit ▸ Reset parameters returns to it)
        self._alpha_hist.clear()
        self.alpha_history.emit((np.zeros(0), np.zeros((0, 3))))
        self._white_follows = True
        self.refresh_exposure()
        self.request_frames()
        self.request_degradation()
        self.request_compare()

    def refresh_exposure(self) -> None:
        """The sequence's α (Bayer streams) and white point (every stream) for the recipe as it is now, as the CLI
        estimates them (when a capture opens, and when η, the window or the colour cast change)."""
        src = self.session.source
        if src is None:
            return
        try:
            recipe = self.session.recipe()
        except Exception as e:  # noqa: BLE001 - a setting the recipe refuses: said, the estimate waits
            self._error(str(e))
            return
        self.preview.submit("alpha", lambda ctx, s=src, r=recipe: jobs.alpha_job(s, r, ctx))

    def follow_capture_white(self) -> None:
        """The white point follows the capture's estimate again (Reset parameters, a new capture), re-estimated
        for the parameters as they are now."""
        self._white_follows = True
        self.refresh_exposure()

    def _on_tick(self, tick: int) -> None:
        self.request_frames()
        if not self.session.playing:
            self.request_degradation()
            self.request_compare()

    def _on_param(self, name: str, value: Any) -> None:
        if name == "white":  # a white point typed or dragged by the user stays; the estimate's follows the capture
            cw = getattr(self, "capture_white", None)
            self._white_follows = cw is not None and value == cw
        elif name in EXPOSURE_PARAMS and self.session.source is not None:
            self.refresh_exposure()  # the white point is Y·α/η of the window: the CLI's changes with them
        group = SPECS[name].group
        if group in _FRAME_GROUPS:
            self.request_frames()
        if group in _FRAME_GROUPS or group == "forward":
            self.request_degradation()
        if group in _FRAME_GROUPS or name == "white":
            self.request_compare()
        restart = group in ("guided", "forward") or name in ("window", "demosaic", "colour_cast")
        if restart and (self.guided.is_active("guided") or self.guided_live):
            self.guided_timer.start()

    def _on_roi(self, roi: Any) -> None:
        self.request_rates()
        self.request_degradation()
        self.request_compare()

    def _on_playback(self, playing: bool) -> None:
        if playing:
            self._last_advance = time.perf_counter()
            self.play_timer.start()
        else:
            self.play_timer.stop()
            self.request_degradation()
            self.request_rates()
            self.request_tfi()  # every pane catches up with the tick playback stopped on
            self.request_compare()

    # ------------------------------------------------------------------------------ playback
    def _play_tick(self) -> None:
        if self.preview.is_active("frames"):
            return  # back-pressure: the last frame is not shown yet
        now = time.perf_counter()
        if now - self._last_advance < 1.0 / MAX_DISPLAY_FPS:
            return  # the play timer comes back in PLAY_INTERVAL_MS
        elapsed, self._last_advance = now - self._last_advance, now
        self.session.advance(elapsed)

    def display_fps(self) -> float:
        """Frames shown per second over the last second or so (0 when idle)."""
        t = self._shown_times
        if len(t) < 2 or time.perf_counter() - t[-1] > 1.0:
            return 0.0
        recent = [x for x in t if t[-1] - x <= 1.0]
        return (len(recent) - 1) / max(recent[-1] - recent[0], 1e-6) if len(recent) > 1 else 0.0

    # ------------------------------------------------------------------------------ previews
    def display_params(self) -> dict[str, Any]:
        """A snapshot of the session's parameters for a job, with the display curve ``auto`` resolved for the open
        capture (:func:`spikeview.transfer.resolve_transfer`: what an export of it writes, pipeline.recipe_for_state)."""
        from spikeview.transfer import resolve_transfer

        params = dict(self.session.params)
        params["tfi_half_window"] = self.session.tfi_search()  # a dark capture's search reaches further, as the CLI's
        if params.get("transfer") == "auto":
            src = self.session.source
            params["transfer"] = resolve_transfer("auto", getattr(src, "info", None))[0]
        return params

    def _request(self, **overrides: Any) -> jobs.PreviewRequest:
        s = self.session
        kw: dict[str, Any] = {"source": s.source, "tick": s.tick, "params": self.display_params(), "alpha": self.alpha,
                              "roi": s.roi, "want_tfi": self.enabled["tfi"], "factor": self.display_factor}
        kw.update(overrides)
        return jobs.PreviewRequest(**kw)

    def request_frames(self) -> None:
        if self.session.source is None:
            return
        if self.preview.is_active("frames") and self.session.playing:
            self._frames_dirty = True
            return
        req = self._request()
        self.preview.submit("frames", lambda ctx, r=req: jobs.frames_job(r, ctx))
        self.request_tfi()

    def request_tfi(self) -> None:
        """The TFI pane: at once when paused, at most every TFI_INTERVAL_MS during playback."""
        if self.session.source is None or not self.enabled["tfi"]:
            return
        if self.session.playing and self.tfi.is_active("tfi"):
            return  # still busy with the last one: playback moves on without it
        self._throttled(self._submit_tfi, self._last_tfi, TFI_INTERVAL_MS, self.tfi_timer)

    def _throttled(self, submit: Any, last: float, interval_ms: float, timer: QtCore.QTimer) -> None:
        """``submit()`` now when paused or when ``interval_ms`` have passed since ``last`` (a perf_counter time);
        otherwise once, by ``timer``, when they have."""
        if not self.session.playing:
            submit()
            return
        wait = interval_ms - (time.perf_counter() - last) * 1000
        if wait <= 0:
            submit()
        elif not timer.isActive():
            timer.start(int(wait))

    def _submit_tfi(self) -> None:
        if self.session.source is None:
            return
        self._last_tfi = time.perf_counter()
        req = self._request()
        self.tfi.submit("tfi", lambda ctx, r=req: jobs.tfi_job(r, ctx))

    def request_rates(self) -> None:
        if self.last_frames is None or not self.enabled["rates"]:
            return
        self._throttled(self._submit_rates, self._last_rates, RATES_INTERVAL_MS, self.rates_timer)

    def _submit_rates(self) -> None:
        f = self.last_frames
        if f is None or self.session.source is None:
            return
        self._last_rates = time.perf_counter()
        req = self._request(tick=f.tick)
        self.preview.submit("rates", lambda ctx, r=req, m=f.mosaic: jobs.rates_job(r, m, ctx))

    def request_redisplay(self, items: dict[str, Any], params: dict[str, Any]) -> None:
        """Convert the canvas's float results for new display levels in the preview worker (:attr:`redisplayed`)."""
        from spikeview.session import core

        self.preview.submit("redisplay", lambda ctx, i=items, p=params: {k: (d, core.show(d, p)) for k, d in i.items()})

    def request_degradation(self) -> None:
        if self.session.source is None or not (self.enabled["degradation"] or self.enabled["pooling"]):
            return
        g = self.guided_result
        s = self.session
        x = None
        label = "TFP"
        if g is not None and g.tick == s.tick and self._guided_key == self._guided_context():
            x, label = g.image, f"guided run {g.run}"
            if self.guided_run > g.run and self.guided.is_active("guided"):  # a newer run refines: say which X this is
                label += f" (run {self.guided_run} running)"
        try:
            recipe = s.recipe()
        except Exception as e:  # a value the recipe refuses: say so, keep the old preview
            self._error(str(e))
            return
        req = self._request(x_override=x, x_label=label, recipe=recipe)
        self.preview.submit("degradation", lambda ctx, r=req: jobs.degradation_job(r, ctx))

    # ------------------------------------------------------------------------------ comparison
    def request_compare(self) -> None:
        """Score TFP and TFI of the window (on the ROI) against the ground truth, after a quiet moment: only when
        the capture has a ground truth, the comparison is shown and playback is paused."""
        s = self.session
        if s.source is None or s.stream is None or s.stream.ground_truth is None or not self.enabled["compare"] or s.playing:
            return
        self.compare_timer.start()

    def submit_compare(self) -> None:
        """Submit the comparison job now (the debounce's end; the screenshot's flow)."""
        s = self.session
        if s.source is None or s.stream is None or s.stream.ground_truth is None:
            return
        try:
            recipe = s.recipe()
        except Exception:  # noqa: BLE001 - the recipe's refusal is said where it is used (frames, degradation)
            return
        req = jobs.CompareRequest(s.source, s.tick, self.display_params(), self.alpha, s.roi, s.stream.ground_truth,
                                  recipe)
        self.scorer.submit("compare", lambda ctx, r=req: jobs.compare_job(r, ctx), cancel_running=True)

    # ------------------------------------------------------------------------------ guided
    def _guided_context(self) -> tuple[Any, ...]:
        s = self.session
        return (id(s.source), s.tick, s.roi, s.get("window"), s.get("eta"), s.get("colour_cast"))

    def run_guided(self) -> int:
        """Start (or restart) a guided reconstruction of the current window; returns the run number."""
        s = self.session
        if s.source is None:
            self._error("Open a capture first (File ▸ Open), then run the guided reconstruction.")
            return self.guided_run
        self.guided_timer.stop()
        self.guided_run += 1
        gt = s.stream.ground_truth if s.stream is not None else None
        try:
            recipe = s.recipe()
        except Exception as e:
            self._error(str(e))
            return self.guided_run
        req = jobs.GuidedRequest(s.source, s.tick, self.display_params(), self.alpha, s.roi, gt, self.guided_run, recipe)
        self._guided_pending_key = self._guided_context()
        self.guided.submit("guided", lambda ctx, r=req: _guided_then_release(r, ctx), cancel_running=True)
        self.guided_started.emit(self.guided_run, s.roi)
        if self.guided_result is not None:
            self._relabel_degradation()  # X's label says a newer run is on its way
        self.guided_state.emit("running", f"Guided run {self.guided_run} started.")
        return self.guided_run

    def _relabel_degradation(self) -> None:
        """Say on the degradation preview shown now that a newer run is on its way: its label only. Recomputing the
        preview here would take a core from the run it announces (0.4 s of CPU at 256², issue 27's knob latency);
        the run's end recomputes it with the new X."""
        view = getattr(self, "last_degradation", None)
        g = self.guided_result
        if view is None or g is None or view.tick != self.session.tick or not view.x_label.startswith(f"guided run {g.run}"):
            return
        label = f"guided run {g.run} (run {self.guided_run} running)"
        if view.x_label != label:
            import dataclasses

            self.last_degradation = dataclasses.replace(view, x_label=label)
            self.degradation_ready.emit(self.last_degradation)

    def cancel_guided(self) -> None:
        self.guided_timer.stop()
        if self.guided.is_active("guided"):
            self.guided.cancel("guided")
            self.guided_state.emit("cancelled", f"Guided run {self.guided_run} cancelled.")

    def _guided_debounced(self) -> None:
        self.run_guided()

    # ------------------------------------------------------------------------------ export
    def start_export(self, out: str | Path, overwrite: bool = False, cluster: str | None = None) -> bool:
        """Export the current frame or the marked range (session's export settings) to ``out``
        (a ``.zarr`` store: in chunks, in-process or on the Dask ``cluster``)."""
        s = self.session
        if s.source is None:
            self._error("Open a capture first, then export.")
            return False
        if self.exporter.is_active():
            self._error("An export is already running: wait for it or cancel it first.")
            return False
        from spikeview.session.presets import session_recipe

        try:
            recipe = session_recipe(s)
            ticks = jobs.export_ticks(recipe, s.n_frames)
        except Exception as e:
            self._error(str(e))
            return False
        folder = Path(out).parent
        if not folder.is_dir():  # said before any work (the export once started and failed at its first write)
            msg = f"Export not started: the folder {folder} does not exist; choose another output or create the folder first."
            self._error(msg)
            self.export_state.emit("failed", msg)
            return False
        name = str(s.stream.path) if s.stream.path is not None else s.stream.label
        roi = s.roi if recipe.run.method == "guided" else None
        req = jobs.ExportRequest(s.source, name, ticks, recipe, self.alpha, Path(out), roi, overwrite, cluster)
        self.exporter.submit("export", lambda ctx, r=req: jobs.export_job(r, ctx))
        self.export_state.emit("running", f"Exporting {len(ticks)} frame(s) to {out}…")
        return True

    def cancel_export(self) -> None:
        self.exporter.cancel("export")

    # ------------------------------------------------------------------------------ results
    def _on_progress(self, channel: str, job_id: int, payload: Any) -> None:
        if channel == "guided":
            if self.guided.is_current(channel, job_id):
                self.guided_update.emit(payload)
        elif channel == "export":
            self.export_progress.emit(*payload)

    def _on_finished(self, channel: str, job_id: int, result: Any) -> None:
        worker = self._worker(channel)
        if channel == "export":
            self.export_done.emit(result)
            self.export_state.emit("done", f"Exported {len(result)} file(s).")
            return
        if not worker.is_current(channel, job_id):
            if channel == "frames":
                self._after_frames()
            return  # stale: a newer job of this channel was submitted
        if channel == "frames":
            self.last_frames = result
            self._shown_times.append(time.perf_counter())
            self.frames_ready.emit(result)
            self.request_rates()
            self._after_frames()
            if self.session.playing:
                # pipeline: the worker computes the next window while this one is painted
                self._play_tick()
        elif channel == "tfi":
            self.tfi_ready.emit(*result)
        elif channel == "compare":
            self.compare_ready.emit(result)
        elif channel == "rates":
            self._alpha_hist[int(result.tick)] = np.asarray(result.alpha, dtype=np.float64)
            if len(self._alpha_hist) > 4000:  # keep memory bounded on very long sessions
                for k in sorted(self._alpha_hist)[:1000]:
                    del self._alpha_hist[k]
            ticks = np.array(sorted(self._alpha_hist))
            self.alpha_history.emit((ticks, np.array([self._alpha_hist[t] for t in ticks])))
            self.rates_ready.emit(result)
        elif channel == "alpha":
            self.alpha, self.alpha_note, white, said, self.session.tfi_reach = result
            self.white_balance_said.emit(said or "", self.alpha)
            if self.alpha_note:
                self._error(self.alpha_note)
            if white is not None:  # the exposure: the sequence's white point, as the CLI chooses it
                from spikeview.session.model import SPECS

                spec = SPECS["white"]
                self.capture_white = float(min(max(white, spec.minimum or 0.0), spec.maximum or white))
                if getattr(self, "_white_follows", True):
                    self.session.set("white", self.capture_white, record=False)
            self.alpha_ready.emit(self.alpha)
            self.request_frames()
            self.request_degradation()
        elif channel == "redisplay":
            self.redisplayed.emit(result)
        elif channel == "degradation":
            self.last_degradation = result
            self.degradation_ready.emit(result)
        elif channel == "guided":
            if not self._heap_settled_after_model:
                self._heap_settled_after_model = True
                self.settle_heap(collect=False)
            self.guided_result = result
            self._guided_key = getattr(self, "_guided_pending_key", None)
            self.guided_done.emit(result)
            msg = f"Guided run {result.run} finished in {result.elapsed:.1f} s"
            if result.psnr is not None:
                msg += f" (PSNR {result.psnr:.2f} dB, SSIM {result.ssim:.3f})"
            self.guided_state.emit("done", msg + ".")
            self.request_degradation()

    def _after_frames(self) -> None:
        if self._frames_dirty:
            self._frames_dirty = False
            self.request_frames()

    def _on_failed(self, channel: str, job_id: int, message: str) -> None:
        if channel == "export":
            self.export_state.emit("failed", message)
            self._error(f"Export failed: {message}")
            return
        worker = self._worker(channel)
        if not worker.is_current(channel, job_id):
            return
        if channel == "guided":
            self.guided_state.emit("failed", message)
        self._error(message)

    def _on_cancelled(self, channel: str, job_id: int) -> None:
        if channel == "export":
            self.export_state.emit("cancelled", "Export cancelled; frames already written were kept.")
        elif channel == "guided" and self.guided.is_current(channel, job_id):
            self.guided_state.emit("cancelled", "Guided run cancelled.")

    def _worker(self, channel: str) -> Worker:
        return {"guided": self.guided, "export": self.exporter, "tfi": self.tfi, "compare": self.scorer}.get(channel, self.preview)

    def _error(self, message: str) -> None:
        self.errors.append(message)
        self.error.emit(message)
