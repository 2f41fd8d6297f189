"""The app's session model, adapters, jobs and presets, driven headless (no Qt imported)."""

from __future__ import annotations

import sys
import threading

import numpy as np
import pytest

from spikeview.errors import Cancelled, InputFileError, ParameterError
from spikeview.session import core, jobs
from spikeview.session.model import (
    SPECS,
    Event,
    OpenedStream,
    Session,
    default_params,
    format_us,
)
from spikeview.io.source import ArraySource


def periodic_stream(h: int = 16, w: int = 16, n: int = 200, period: int = 4, cfa: str | None = "RGGB") -> OpenedStream:
    """Every photosite fires once every ``period`` ticks (phase by column), so TFP over a multiple
    of ``period`` ticks is exactly ``1/period`` everywhere."""
    t = np.arange(n)[:, None, None]
    phase = np.arange(w)[None, None, :] % period
    spikes = ((t + phase) % period == 0).astype(np.uint8) * np.ones((1, h, 1), np.uint8)
    return core.memory_stream(ArraySource(spikes, cfa=cfa), "periodic")


class Ctx:
    """A job context like the worker's (see spikeview.gui.workers.JobContext)."""

    def __init__(self) -> None:
        self.cancelled = threading.Event()
        self.state: dict = {}
        self.reports: list = []

    def report(self, payload) -> None:
        self.reports.append(payload)

    def check(self) -> None:
        if self.cancelled.is_set():
            raise Cancelled("cancelled")


# ---------------------------------------------------------------------------------------- events
def test_event_connect_emit_disconnect_in_order():
    ev, calls = Event("x"), []
    a = ev.connect(lambda v: calls.append(("a", v)))
    ev.connect(lambda v: calls.append(("b", v)))
    ev.emit(1)
    ev.disconnect(a)
    ev.emit(2)
    ev.disconnect(a)  # twice is fine
    assert calls == [("a", 1), ("b", 1), ("b", 2)]


def test_model_imports_no_qt():
    code = "import sys, spikeview.session.model, spikeview.session.core, spikeview.session.jobs, spikeview.session.presets; " \
           "print([m for m in ('PySide6', 'pyqtgraph') if m in sys.modules])"
    import subprocess

    out = subprocess.run([sys.executable, "-c", code], check=False, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[]"


# ---------------------------------------------------------------------------------- parameters
def test_set_validates_and_emits_once():
    s = Session()
    seen = []
    s.events.param_changed.connect(lambda n, v: seen.append((n, v)))
    s.set("k", 25)
    s.set("k", 25.0)  # same value: no event
    assert seen == [("k", 25.0)] and isinstance(s.get("k"), float)
    with pytest.raises(ParameterError, match="Quantiser sharpness k = -1 is out of range"):
        s.set("k", -1.0)
    with pytest.raises(ParameterError, match="is not valid: use one of"):
        s.set("guidance", "magic")
    with pytest.raises(ParameterError, match="whole number"):
        s.set("steps", 2.5)
    with pytest.raises(ParameterError, match="Unknown parameter"):
        s.set("nope", 1)
    assert s.get("k") == 25.0


def test_defaults_match_the_core_configs():
    from spikeview.classical.reconstruct import ClassicalConfig
    from spikeview.guided.config import GuidedConfig

    d, g, c = default_params(), GuidedConfig(), ClassicalConfig()
    for name in ("steps", "s", "k", "levels", "t_start", "guidance", "prior", "seed", "window", "eta"):
        assert d[name] == getattr(g, name), name
    for name in ("window", "tfi_half_window", "demosaic", "colour_cast", "eta"):
        assert d[name] == getattr(c, name), name


def test_undo_redo_and_one_drag_is_one_step():
    s = Session()
    s.set("k", 10.0)
    s.begin_group("k drag")  # slider pressed ...
    for v in (11.0, 12.0, 13.0, 40.0):
        s.set("k", v)
    s.end_group()  # ... released
    s.set("speed", "realtime")  # playback settings are not undoable
    assert s.undo_text() == ("k drag", None)
    assert s.undo() and s.get("k") == 10.0
    assert s.undo() and s.get("k") == SPECS["k"].default
    assert not s.undo()
    assert s.redo() and s.get("k") == 10.0
    assert s.redo() and s.get("k") == 40.0
    assert s.get("speed") == "realtime"


def test_group_that_returns_to_the_start_leaves_no_step_and_new_change_clears_redo():
    s = Session()
    with s.undo_group("drag"):
        s.set("eta", 3.0)
        s.set("eta", 2.0)
    assert not s.undo_stack.can_undo
    s.set("eta", 3.0)
    s.undo()
    s.set("eta", 1.0)
    assert not s.undo_stack.can_redo


def test_update_params_is_atomic_and_one_step():
    s = Session()
    with pytest.raises(ParameterError):
        s.update_params({"k": 30.0, "steps": 0})
    assert s.get("k") == SPECS["k"].default  # nothing applied
    s.update_params({"k": 30.0, "steps": 4, "eta": 1.5}, label="Preset")
    assert s.undo_text()[0] == "Preset"
    s.undo()
    assert s.params == default_params()
    assert s.update_params({"k": 31.0, "gone": 1, "steps": -3}, strict=False) == ["gone", "steps"]


# -------------------------------------------------------------------------------- time, playback
def test_open_stream_resets_tick_marks_and_shrinks_window():
    s = Session({"window": 500})
    msgs = []
    s.events.message.connect(msgs.append)
    s.open_stream(periodic_stream(n=100))
    assert s.tick == 50 and s.get("window") == 100
    assert msgs and "shortened to 100" in msgs[0]
    assert s.window_range() == (0, 100)


def test_window_range_matches_the_core_rule():
    s = Session({"window": 10})
    s.open_stream(periodic_stream(n=200))
    for t in (0, 3, 100, 196, 199):
        s.set_tick(t)
        assert s.window_range() == core.window_range(t, 10, 200)


def test_scrub_clamps_and_time_text():
    s = Session()
    s.open_stream(periodic_stream(n=200))
    s.set_tick(10_000)
    assert s.tick == 199
    s.step(-300)
    assert s.tick == 0
    s.set_tick(20)
    assert s.time_text() == f"tick 20 / 199 · {format_us(1000)}"  # 20 ticks × 50 µs
    assert format_us(61700) == "61\u2009700 µs"


def test_advance_every_window_loops_over_marks():
    s = Session({"window": 10, "speed": "window", "loop": True})
    s.open_stream(periodic_stream(n=200))
    s.set_tick(100)
    s.set_mark_in()
    s.set_tick(125)
    s.set_mark_out()
    s.set_tick(100)
    s.set_playing(True)
    assert [s.advance(0.0) for _ in range(4)] == [110, 120, 100, 110]


def test_advance_real_time_and_slow_motion_carry_fractions():
    s = Session({"speed": "realtime"})
    s.open_stream(periodic_stream(n=2000))
    s.set_tick(0)
    s.set_playing(True)
    assert s.advance(0.01) == 200  # 10 ms at 20 kHz
    s.set("speed", "slowmo")
    s.set("slowmo", 2000)  # 10 ticks per second
    ticks = [s.advance(0.03) for _ in range(10)]  # 0.3 ticks per frame
    assert ticks[-1] == 203 and ticks[0] == 200


def test_advance_stops_at_the_end_without_loop():
    s = Session({"window": 50, "speed": "window", "loop": False})
    s.open_stream(periodic_stream(n=200))
    s.set_tick(180)
    s.set_playing(True)
    assert s.advance(0.0) == 199 and not s.playing
    s.set_playing(True)  # parked at the end: play starts over
    assert s.tick == 0 and s.playing


def test_roi_is_clipped_and_full_frame_means_none():
    s = Session()
    s.open_stream(periodic_stream(16, 16))
    s.set_roi((-4, 2, 10, 40))
    assert s.roi == (0, 2, 6, 14)
    s.set_roi((0, 0, 16, 16))
    assert s.roi is None


def test_reinterpret_flip_keeps_the_physical_cfa():
    s = Session()
    s.open_stream(periodic_stream(16, 16, cfa="RGGB"))
    s.set_tick(77)
    s.reinterpret(flip_vertical=True)
    assert s.source.cfa == "GBRG" and s.tick == 77  # even height: row parity swaps
    s.reinterpret(cfa="BGGR")
    assert s.source.cfa == "BGGR" and s.source.info.flip_vertical


# ------------------------------------------------------------------------------ core adapters
def test_stream_frames_of_a_periodic_stream():
    st = periodic_stream(16, 16, n=200, period=4, cfa=None)
    p = default_params() | {"window": 8, "transfer": "linear"}
    f = core.stream_frames(st.source, 100, p, None)
    assert (f.a, f.b) == (96, 104)
    assert f.raw.dtype == np.uint8 and set(np.unique(f.raw)) <= {0, 255}
    np.testing.assert_allclose(f.mosaic, 0.25)  # fires 2 of 8 ticks
    assert f.spike_rate == pytest.approx(0.25)
    assert f.tfp.shape == (16, 16, 3) and f.tfp.dtype == np.uint8
    assert np.all(np.abs(f.tfp.astype(int) - 64) <= 1)  # 0.25 → 63.75, linear
    assert f.tfi is not None and np.all(np.abs(f.tfi.astype(int) - 64) <= 1)  # interval 4 → 1/4


def test_site_rates_histogram_and_roi():
    sfr = np.full((8, 8), 0.2, np.float32)
    sfr[0::2, 0::2] = 0.6  # the R sites of RGGB
    r = core.site_rates(sfr, "RGGB", window=10)
    assert set(r.hists) == {"R", "Gr", "Gb", "B"}
    centres = (r.edges[:-1] + r.edges[1:]) / 2
    assert centres[np.argmax(r.hists["R"])] == pytest.approx(0.6)
    assert centres[np.argmax(r.hists["Gb"])] == pytest.approx(0.2)
    assert r.hists["B"].sum() == pytest.approx(1.0)
    np.testing.assert_allclose(r.alpha, [1 / 0.6, 1 / 0.2, 1 / 0.2], rtol=1e-6)
    roi = core.site_rates(sfr, "RGGB", 10, roi=(2, 2, 2, 2))
    assert roi.means["R"] == pytest.approx(0.6)


def test_alpha_of_a_dark_channel_falls_back_without_warning():
    alpha, note = core.alpha_note(np.array([0.2, 0.4, 0.0]))
    np.testing.assert_allclose(alpha, [5.0, 2.5, 1 / 0.3], rtol=1e-6)
    assert note is not None and "channel B has no spikes" in note


def test_cfa_hint_flags_unequal_greens():
    from spikeview.gui.panels.rates import cfa_hint

    assert cfa_hint({"R": 0.2, "Gr": 0.3, "Gb": 0.31, "B": 0.1}) == ""
    assert "flip" in cfa_hint({"R": 0.2, "Gr": 0.3, "Gb": 0.1, "B": 0.1})
    assert "CFA is probably wrong" in cfa_hint({"R": 0.4, "Gr": 0.1, "Gb": 0.1, "B": 0.3})


def _stages(x, y, alpha, eta, levels, quantise=True, k=500.0, window=8):
    from spikeview.guided.baseline import to_tensor
    from spikeview.guided.config import GuidedConfig
    from spikeview.guided.observation import Observation
    from spikeview.guided.plan import make_plan
    from spikeview.guided.sampler import GuidedSampler

    obs = Observation(y, "RGGB", window, np.asarray(alpha, np.float64), eta)
    cfg = GuidedConfig(k=k, quantise=quantise, levels=levels, window=window, eta=eta, use_cast=True)
    plan = make_plan(obs, cfg)
    return GuidedSampler.data_term(obs, plan, cfg).stages(to_tensor(x))


def test_degradation_preview_shows_the_samplers_own_data_term():
    # X grey 0.5, α = (2, 4, 8), η = 2: C M X = 0.5·2/α = (0.5, 0.25, 0.125) per site; Y on the
    # 8-level grid holds exactly those values, and k = 500 makes Q nearly hard rounding.
    h = w = 8
    x = np.full((h, w, 3), 0.5, np.float32)
    alpha = np.array([2.0, 4.0, 8.0])
    from spikeview.cfa import channel_map

    y = np.array([0.5, 0.25, 0.125], np.float32)[channel_map("RGGB", h, w)]
    p = default_params()
    res = core.stage_images(x, _stages(x, y, alpha, 2.0, 1), p, True)
    assert res.rmse < 0.01
    assert set(res.images) == {"x", "mx", "cmx", "qcmx", "y", "residual"}
    assert all(im.dtype == np.uint8 for im in res.images.values())
    assert [b.shape for b in res.bands] == [(8, 8), (4, 4)]  # L = 1: one band-pass level + the coarse residual
    wrong = core.stage_images(x, _stages(x, y, alpha, 1.0, 0), p, False)  # η halves C M X
    assert wrong.rmse > 0.05 and wrong.bands == []
    # Q is what the sampler runs: off, the quantised stage is C M X itself; on with a soft k it differs
    st_off = _stages(x + 0.03, y, alpha, 2.0, 0, quantise=False)
    assert torch_equal(st_off["a"], st_off["cmx"])
    st_on = _stages(x + 0.03, y, alpha, 2.0, 0, quantise=True, k=50.0)
    assert not torch_equal(st_on["a"], st_on["cmx"])


def torch_equal(a, b) -> bool:
    import torch

    return bool(torch.equal(a, b))


# ---------------------------------------------------------------------------------------- jobs
def test_export_ticks_follow_the_recipes_run_table():
    from spikeview.recipe import Recipe

    r = Recipe().with_values({"classical.window": 10, "run.at": 42})
    assert jobs.export_ticks(r, 100) == (42,)
    r = r.with_values({"run.at": None, "run.range": "20:56:10"})
    assert jobs.export_ticks(r, 100) == (20, 30, 40, 50)


def test_guided_job_reports_every_step_and_cancels(tmp_path):
    st = periodic_stream(16, 16, n=100, period=3)
    gt = np.full((16, 16, 3), 0.5, np.float32)
    from spikeview.recipe import Recipe

    p = default_params() | {"steps": 3}
    recipe = Recipe().with_values({"guided.steps": 3, "guided.diffusion": "always"})
    req = jobs.GuidedRequest(st.source, 50, p, np.array([3.0, 3.0, 3.0]), None, lambda t: gt, run=7, recipe=recipe)
    ctx = Ctx()
    res = jobs.guided_job(req, ctx)
    steps = [u for u in ctx.reports if u.kind == "step"]
    assert ctx.reports[0].kind == "plan" and "mosaic" in ctx.reports[0].text
    assert [u.step for u in steps] == [1, 2, 3] and all(u.run == 7 for u in steps)
    assert all(u.psnr is not None and u.preview.dtype == np.uint8 for u in steps)
    assert res.image.shape == (16, 16, 3) and res.psnr is not None
    ctx2 = Ctx()
    ctx2.cancelled.set()
    with pytest.raises(Cancelled):
        jobs.guided_job(req, ctx2)


# ------------------------------------------------------------------------------------- presets
APP_ONLY = {"speed", "slowmo", "loop", "show_pyramid", "export_format", "export_range"}


def test_preset_round_trip_through_the_core_configs(tmp_path):
    from spikeview.config import load_toml
    from spikeview.session.presets import load_preset, save_preset

    a = Session()
    a.update_params({"k": 75.0, "steps": 12, "guidance": "dps", "eta": 1.5, "window": 20, "demosaic": "malvar2004",
                     "export_fps": 24.0, "transfer": "gamma", "gamma": 1.8, "export_method": "tfi", "speed": "slowmo"})
    path = save_preset(a, tmp_path / "p.toml")
    data = load_toml(path)
    assert set(data) == {"run", "classical", "guided", "export"}  # no capture open: no [stream]
    assert data["guided"]["k"] == 75.0 and data["classical"]["window"] == 20 and data["export"]["fps"] == 24.0
    b = Session()
    load_preset(b, path)
    assert {k: v for k, v in b.params.items() if k not in APP_ONLY} == {k: v for k, v in a.params.items() if k not in APP_ONLY}
    assert b.get("speed") == default_params()["speed"]  # playback settings are not part of a preset
    assert b.undo_text()[0] == "Load preset p.toml"


def test_the_cli_runs_the_apps_preset_and_the_app_loads_the_clis(tmp_path):
    from spikeview.cli.main import main
    from spikeview.config import load_toml
    from spikeview.session.presets import load_preset, save_preset
    from spikeview.io import write_plain

    spikes = periodic_stream(16, 16, n=60, period=3).source.read(0, 60)
    dat = tmp_path / "c.dat"
    write_plain(dat, spikes, cfa="RGGB")
    s = Session()
    s.open_stream(core.open_file(dat))
    s.update_params({"window": 12, "eta": 1.5, "demosaic": "malvar2004"})
    s.set_tick(30)
    preset = save_preset(s, tmp_path / "app.toml")
    assert load_toml(preset)["stream"]["cfa"] == "RGGB" and load_toml(preset)["run"] == {"method": "tfp", "at": 30}
    out = tmp_path / "frame.png"
    assert main(["reconstruct", str(dat), "--preset", str(preset), "--out", str(out)]) == 0
    assert out.exists()
    cli_preset = load_toml(tmp_path / "frame.png.preset.toml")
    assert cli_preset["classical"]["window"] == 12 and cli_preset["run"]["at"] == 30
    t = Session()
    load_preset(t, tmp_path / "frame.png.preset.toml")
    assert (t.get("window"), t.get("eta"), t.get("demosaic")) == (12, 1.5, "malvar2004")


def test_bad_preset_names_the_file_and_changes_nothing(tmp_path):
    from spikeview.session.presets import load_preset

    bad = tmp_path / "bad.toml"
    bad.write_text("[guided]\nsteps = 0\n")
    s = Session()
    with pytest.raises(ParameterError, match="bad.toml"):
        load_preset(s, bad)
    (tmp_path / "x.toml").write_text("[run]\nmethod = 'tfp'\n")
    with pytest.raises(InputFileError, match="not a spikeview preset"):
        load_preset(s, tmp_path / "x.toml")
    (tmp_path / "y.toml").write_text("[app]\nk = 1\n")
    with pytest.raises(ParameterError, match="unknown table"):
        load_preset(s, tmp_path / "y.toml")
    assert s.params == default_params()


def test_every_spec_default_validates():
    for spec in SPECS.values():
        assert spec.validate(spec.default) == spec.default


def test_downsample_is_a_rounded_block_mean():
    img = np.arange(36, dtype=np.uint8).reshape(6, 6)
    out = core.downsample(img, 3)
    assert out.shape == (2, 2) and out.dtype == np.uint8
    np.testing.assert_array_equal(out, [[7, 10], [25, 28]])  # mean of rows 0-2 × cols 0-2 is 7, …
    rgb = np.zeros((5, 7, 3), np.uint8)
    rgb[..., 1] = 255
    assert core.downsample(rgb, 2).shape == (2, 3, 3)  # edges cropped to a multiple
    assert core.downsample(rgb, 1) is rgb


def test_psnr_ssim_match_scikit_image():
    from skimage.metrics import peak_signal_noise_ratio, structural_similarity

    from spikeview import metrics

    rng = np.random.default_rng(3)
    gt = rng.random((24, 30, 3))
    x = np.clip(gt + 0.05 * rng.standard_normal(gt.shape), 0, 1)
    psnr, ssim = metrics.psnr_ssim(x, gt, data_range=1.0)
    assert psnr == pytest.approx(peak_signal_noise_ratio(gt, x, data_range=1.0), rel=1e-9)
    assert ssim == pytest.approx(structural_similarity(gt, x, data_range=1.0, channel_axis=-1), rel=1e-9)
    assert metrics.psnr_ssim(gt, gt)[1] == pytest.approx(1.0)
    # the range is explicit: the same images on a 0..255 scale give the same numbers
    assert metrics.psnr(255 * x, 255 * gt, data_range=255.0) == pytest.approx(psnr, rel=1e-9)
    assert metrics.ssim(255 * x, 255 * gt, data_range=255.0) == pytest.approx(ssim, rel=1e-9)
    with pytest.raises(ParameterError, match="data_range"):
        metrics.ssim(x, gt, data_range=0.0)


def test_tfi_frame_and_rates_of_a_periodic_stream():
    st = periodic_stream(16, 16, n=200, period=5, cfa=None)
    img = core.tfi_frame(st.source, 100, default_params() | {"transfer": "linear"}, None)
    assert img.shape == (16, 16, 3) and np.all(np.abs(img.astype(int) - 51) <= 1)  # 1/5 → 51
    f = core.stream_frames(st.source, 100, default_params() | {"window": 10}, None, want_tfi=False)
    r = core.site_rates(f.mosaic, None, 10)
    assert list(r.hists) == ["all"] and r.hists["all"][2] == pytest.approx(1.0)  # all at 2/10


def test_ground_truth_alignment_recovers_per_channel_sensor_gain():
    """A reconstruction equal to the gray-world-corrected truth must score perfectly after alignment."""
    import numpy as np

    from spikeview.cfa import channel_map
    from spikeview.metrics import align_ground_truth, psnr_ssim

    rng = np.random.default_rng(5)
    gt = rng.uniform(0.05, 0.6, size=(16, 16, 3)).astype(np.float32)
    gains = np.array([0.36, 0.6, 0.3])  # rate·spectral gain of the simulated sensor
    cmap = channel_map("RGGB", 16, 16)
    y = np.take_along_axis(gt, cmap[..., None].astype(np.int64), axis=-1)[..., 0] * gains[cmap]
    alpha, eta = np.array([3.0, 2.0, 4.0]), 2.0
    expected = gt * gains * alpha / eta  # what a perfect corrected reconstruction shows
    aligned = align_ground_truth(gt, y.astype(np.float32), "RGGB", alpha, eta)
    np.testing.assert_allclose(aligned, np.clip(expected, 0, 1), rtol=1e-5, atol=1e-6)
    assert psnr_ssim(np.clip(expected, 0, 1).astype(np.float32), gt)[0] < 30  # unaligned: scales differ


@pytest.mark.parametrize("cfa", ["RGGB", None], ids=["bayer", "mono"])
def test_the_apps_tfp_and_tfi_previews_are_the_clis_frames_on_a_corrected_capture(tmp_path, cfa):
    """A capture whose own dark rate and hot photosites are corrected (spikeview.classical.calibration.attach, as the CLI
    and the app open it): the Stream panel's TFP and TFI previews are the CLI's PNG frames for the same settings
    (within one code value: the CLI rounds its float frame once more). Before, the previews skipped the correction and
    decided TFI's demosaic on the uncorrected mosaic: a dark capture's TFI pane was lilac where its export was not."""
    import imageio.v3 as iio

    from spikeview.classical.calibration import camera_of
    from spikeview.cli.main import main
    from spikeview.io import write_plain

    rng = np.random.default_rng(5)
    scene = 0.002 + 0.03 * np.kron(rng.random((8, 8)), np.ones((8, 8)))  # plus a dark rate everywhere
    scene[:16, :16] = 0.004  # a dark patch (with the dark rate: a colour capture's floors agree there)
    v = rng.random(scene.shape)
    s = np.zeros((300, 64, 64), np.uint8)
    for t in range(300):
        v += scene
        s[t] = v >= 1
        v -= s[t]
    s[:, 40, 41] = 1  # a hot photosite
    path = write_plain(tmp_path / "c.dat", s, cfa=cfa)
    st = core.open_file(path)
    assert camera_of(st.source) is not None and camera_of(st.source).hot[40, 41]
    sess = Session()
    sess.open_stream(st)

    class Ctx:
        state: dict = {}

    alpha, _note, white, _said, reach = jobs.alpha_job(st.source, sess.recipe(), Ctx())
    sess.tfi_reach = reach
    p = dict(sess.params, white=white, transfer="srgb", tfi_half_window=sess.tfi_search())
    frames = core.stream_frames(st.source, 150, p, alpha, want_tfi=True)
    assert np.array_equal(frames.tfi, core.tfi_frame(st.source, 150, p, alpha))
    for method, shown in (("tfp", frames.tfp), ("tfi", frames.tfi)):
        out = tmp_path / f"{method}.png"
        assert main(["reconstruct", str(path), "--method", method, "--at", "150", "--out", str(out)]) == 0
        cli = iio.imread(out)
        cli = cli[..., :3] if cli.ndim == 3 else np.repeat(cli[..., None], 3, axis=-1)
        assert np.abs(shown.astype(int) - cli.astype(int)).max() <= 1, method
