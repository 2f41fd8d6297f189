"""The integrate-and-fire sensor model: mean rates, determinism, each noise term, motion, alignment."""

import numpy as np
import pytest
from scipy.ndimage import gaussian_filter

from spikeview.cfa import channel_map
from spikeview.errors import Cancelled, ParameterError
from spikeview.sim import simulator as simulator_module
from spikeview.sim.config import NOISE_SWITCHES, SimConfig
from spikeview.sim.scenes import ArrayScene, Fan, MotionScene, StaticScene
from spikeview.sim.simulator import SpikeSimulator, simulate

GAINS = (0.6, 1.0, 0.5)


def _random_image(seed, h=16, w=16):
    return np.random.default_rng(seed).uniform(0.0, 1.0, (h, w, 3)).astype(np.float32)


def _texture(seed, h, w, sigma=2.5):
    """Smooth random texture in [0.1, 0.9] (linear), the same in the three channels."""
    n = gaussian_filter(np.random.default_rng(seed).standard_normal((h, w)), sigma, mode="wrap")
    n = (n - n.min()) / (n.max() - n.min())
    g = (0.1 + 0.8 * n).astype(np.float32)
    return np.repeat(g[..., None], 3, axis=2)


# ------------------------------------------------------------------------------- ideal sensor
@pytest.mark.parametrize("cfa", ["RGGB", "GBRG"])
def test_noiseless_rate_is_intensity_times_rate_times_gain(cfa):
    img = _random_image(1)
    T = 2000
    cap = simulate(StaticScene(img), SimConfig.noiseless(n_ticks=T, cfa=cfa, spectral_gains=GAINS, rate=0.6))
    chan = channel_map(cfa, 16, 16)
    intensity = np.take_along_axis(img, chan[..., None].astype(np.intp), axis=2)[..., 0].astype(np.float64)
    expected = 0.6 * np.asarray(GAINS)[chan] * intensity
    measured = cap.count(0, T) / T
    # count = floor(v0 + T·a) with v0 in [0, 1), so |count/T − a| < 1/T; 1e-6 covers the float32
    # rounding of the per-pixel gain (relative 6e-8, times T·a ≤ T ticks)
    assert np.abs(measured - expected).max() < 1.0 / T + 1e-6
    # and it is not trivially satisfied: the channels really differ
    assert measured[chan == 1].mean() > 1.5 * measured[chan == 2].mean()


def test_noiseless_monochrome_sees_rec709_luminance():
    img = _random_image(2)
    T = 1500
    cap = simulate(StaticScene(img), SimConfig.noiseless(n_ticks=T, cfa="none", rate=0.6))
    assert cap.cfa is None
    expected = 0.6 * (img.astype(np.float64) @ np.array([0.2126, 0.7152, 0.0722]))
    # same bound as above; 1e-6 also covers the float32 luminance sum
    assert np.abs(cap.count(0, T) / T - expected).max() < 1.0 / T + 1e-6


def test_expected_rate_of_the_sensor_pattern_holds_with_fixed_pattern_noise():
    img = _random_image(3)
    T = 2000
    cfg = SimConfig.noiseless(n_ticks=T, dark_current=True, prnu=True, threshold_fpn=True, seed=5)
    cap = simulate(StaticScene(img), cfg)
    # a fixed pattern is still a deterministic integrate-and-fire: the count is within one spike
    # of T · (drive·I + dark)·cap_ratio/theta, whatever the per-pixel constants
    expected = cap.sensor.expected_rate(img)
    assert np.abs(cap.count(0, T) / T - expected).max() < 1.0 / T + 1e-6


def test_saturation_at_one_spike_per_tick_with_all_noise_on():
    T = 400
    white = np.ones((32, 32, 3), np.float32)
    cap = simulate(StaticScene(white), SimConfig(n_ticks=T, rate=4.0, seed=3))
    # the weakest photosite gains ≥ 4 · 0.5 · (1 − 5.3·0.058) ≈ 1.4 threshold per tick, above
    # any threshold (1 + 6·0.0497 ≈ 1.3) plus jitter (≤ 3.7·0.0064): every tick must fire,
    # and the stored charge is capped, so nothing more than one spike per tick can come out
    spikes = cap.read(0, T)
    assert spikes.max() == 1
    assert np.all(spikes == 1)


def test_reset_slowdown_lowers_the_rate_as_predicted():
    T = 10000
    white = np.ones((8, 8, 3), np.float32)
    base = SimConfig.noiseless(n_ticks=T, rate=0.5, spectral_gains=(1.0, 1.0, 1.0))
    off = simulate(StaticScene(white), base).count(0, T).astype(np.int64)
    on = simulate(StaticScene(white), base.replace(reset_slowdown=True)).count(0, T).astype(np.int64)
    # the tick after each spike integrates f = 0.998 of a, so the rate r solves
    # r = a·(1 − (1 − f)·r), i.e. r = a / (1 + (1 − f)·a) = 0.4995 for a = 0.5; counts are
    # within one spike of T·r (one quantisation step, plus one for the start-up transient)
    r = 0.5 / (1 + 0.002 * 0.5)
    assert np.abs(off - 5000).max() <= 1
    assert np.abs(on - T * r).max() <= 2
    assert on.mean() < off.mean() - 3


# ------------------------------------------------------------------------------- determinism
def test_same_seed_same_bytes_different_seed_different_bytes():
    img = _random_image(4, 24, 24)
    cfg = SimConfig(n_ticks=300, seed=11)
    a = simulate(StaticScene(img), cfg).packed.tobytes()
    b = simulate(StaticScene(img), cfg).packed.tobytes()
    c = simulate(StaticScene(img), cfg.replace(seed=12)).packed.tobytes()
    assert a == b
    assert a != c


def test_chunking_and_threads_do_not_change_the_stream(monkeypatch):
    img = _random_image(5, 24, 24)
    cfg = SimConfig(n_ticks=257, seed=2)
    whole = simulate(StaticScene(img), cfg).read(0, 257)
    sim = SpikeSimulator(StaticScene(img), cfg)
    parts = [sim.run(n) for n in (1, 100, 56, 100)]
    assert np.array_equal(np.concatenate(parts), whole)
    monkeypatch.setattr(simulator_module, "PARALLEL_MIN_PIXELS", 0)
    monkeypatch.setenv("SPIKEVIEW_THREADS", "3")  # bands of 8 rows in three threads
    assert np.array_equal(simulate(StaticScene(img), cfg).read(0, 257), whole)


def test_switching_one_noise_term_leaves_the_other_draws_unchanged():
    cfg = SimConfig(seed=9)
    full = simulator_module.SensorPattern.build(cfg, 16, 16)
    no_dark = simulator_module.SensorPattern.build(cfg.replace(dark_current=False), 16, 16)
    assert np.array_equal(full.drive, no_dark.drive)
    assert np.array_equal(full.theta, no_dark.theta)
    assert np.array_equal(full.v0, no_dark.v0)
    assert not np.array_equal(full.dark, no_dark.dark)


# ------------------------------------------------------------------------------- noise terms
def test_dark_current_makes_a_black_scene_fire_at_the_documented_rate():
    T = 4000
    black = np.zeros((32, 32, 3), np.float32)
    clean = simulate(StaticScene(black), SimConfig.noiseless(n_ticks=T))
    assert clean.count(0, T).max() == 0
    cfg = SimConfig.noiseless(n_ticks=T, dark_current=True, seed=1)
    dark = simulate(StaticScene(black), cfg)
    rate = dark.count(0, T) / T
    # 0.4442 pA over 1/20000 s is 138.6 e-, over 27,139 e- per threshold: 0.00511 spikes/tick
    assert cfg.dark_threshold_per_tick == pytest.approx(0.005108, rel=1e-3)
    # the pixel mean estimates the mean of N(0.4442, 0.1731) pA clipped at 0 (clipping adds
    # < 0.1 %): the sample mean of 1024 pixels has a relative error of 0.1731/0.4442/32 = 1.2 %,
    # so 5 % is 4 standard errors; quantisation (±1/T per pixel, zero-mean) is negligible
    assert rate.mean() == pytest.approx(cfg.dark_threshold_per_tick, rel=0.05)
    assert (rate > 0).mean() > 0.9


def _uniform_rates(cfg, value=0.5, T=2000, size=32):
    grey = np.full((size, size, 3), value, np.float32)
    cap = simulate(StaticScene(grey), cfg.replace(n_ticks=T, cfa="none"))
    return cap, cap.count(0, T) / T


def test_prnu_and_threshold_fpn_spread_rates_in_space_but_not_in_time():
    base = SimConfig.noiseless(seed=4)
    T = 2000
    _, flat = _uniform_rates(base, T=T)
    a = 0.6 * 0.5
    # ideal sensor: counts differ only by quantisation (at most one spike)
    assert flat.max() - flat.min() <= 1.0 / T + 1e-9
    for switch, rel_spread in (("prnu", 0.058), ("threshold_fpn", 0.0497)):
        cap, rates = _uniform_rates(base.replace(**{switch: True}), T=T)
        # rate ∝ PRNU gain (std 5.8 %) or ∝ 1/threshold (std 0.0497/1 V, to first order; the
        # capacitance adds 0.3 % in quadrature): the sample std over 1024 pixels has a relative
        # standard error of 1/sqrt(2·1024) = 2.2 %, and quantisation adds 1/T = 0.0005 at most,
        # so ±12 % is > 5 standard errors
        assert rates.std() == pytest.approx(a * rel_spread, rel=0.12)
        # temporal behaviour stays deterministic: every pixel's windowed counts take at most two
        # neighbouring values (a periodic spike train), exactly as without noise
        counts = cap.read(0, T).reshape(T // 20, 20, 32, 32).sum(axis=1)
        assert (counts.max(axis=0) - counts.min(axis=0)).max() <= 1


def _windowed_counts(cfg, T=2000, window=10):
    white = np.ones((32, 32, 3), np.float32)
    # a = 0.5 exactly (rate 0.5, gain 1, intensity 1): without noise every 10-tick window holds
    # exactly 5 spikes, so any temporal variance comes from the noise
    cap = simulate(StaticScene(white), cfg.replace(n_ticks=T, rate=0.5, spectral_gains=(1.0, 1.0, 1.0)))
    return cap.read(0, T).reshape(T // window, window, 32, 32).sum(axis=1, dtype=np.int64), cap


def test_shot_noise_raises_the_temporal_variance_of_windowed_counts():
    base = SimConfig.noiseless(seed=6)
    clean, _ = _windowed_counts(base)
    assert clean.var() == 0.0
    noisy, cap = _windowed_counts(base.replace(shot_noise=True))
    # a window's count leaves 5 when the charge noise δ ~ N(0, σ_w) moves a spike across the
    # window edge: with uniform phase P(count ≠ 5) = E|δ| = 0.798·σ_w, σ_w = sqrt(5 / 27,139)
    # threshold = 0.0136, so var ≈ 0.0108; 204,800 windows make its standard error ≈ 2 %
    predicted = 0.798 * np.sqrt(5 / SimConfig().electrons_per_threshold)
    assert noisy.var() == pytest.approx(predicted, rel=0.15)
    # and the mean rate stays unbiased (per-pixel count std over T is sqrt(1000/27139) = 0.2)
    assert abs(cap.count(0, 2000).mean() / 2000 - 0.5) < 1 / 2000


def test_threshold_jitter_moves_spikes_by_a_tick_without_biasing_the_rate():
    base = SimConfig.noiseless(seed=7)
    noisy, cap = _windowed_counts(base.replace(threshold_jitter=True))
    # jitter (σ = 0.0064 threshold) delays or advances a spike by one tick when the voltage
    # lands within a few σ of the threshold: windowed counts vary, by one spike at most
    assert noisy.var() > 0.002
    assert np.abs(noisy - 5).max() == 1
    # the reset subtracts the fixed threshold, so charge is conserved and the rate unbiased:
    # every pixel stays within 2 spikes (one per window edge) of T·a
    assert np.abs(cap.count(0, 2000).astype(np.int64) - 1000).max() <= 2


def test_every_noise_switch_is_in_the_config_and_defaults_on():
    cfg = SimConfig()
    assert all(getattr(cfg, name) for name in NOISE_SWITCHES)
    assert not any(SimConfig.noiseless().noise_on.values())
    with pytest.raises(ParameterError, match="noise switch"):
        cfg.with_noise(False, thermal=True)


# ------------------------------------------------------------------------------- motion, ground truth
def _motion_between(first, last, max_shift=20, core=slice(20, 44)):
    """Content motion (dy, dx) from ``first`` to ``last``: the integer shift minimising the mean
    squared difference of ``last[core]`` and ``first[core − shift]``, plus a parabolic sub-pixel
    refinement along each axis."""

    def err(dy, dx):
        ys = slice(core.start - dy, core.stop - dy)
        xs = slice(core.start - dx, core.stop - dx)
        return float(np.mean((last[core, core] - first[ys, xs]) ** 2))

    shifts = [(dy, dx) for dy in range(-max_shift, max_shift + 1) for dx in range(-max_shift, max_shift + 1)]
    dy, dx = min(shifts, key=lambda s: err(*s))

    def vertex(em, e0, ep):
        return 0.5 * (em - ep) / (em - 2 * e0 + ep)

    e0 = err(dy, dx)
    return (dy + vertex(err(dy - 1, dx), e0, err(dy + 1, dx)), dx + vertex(err(dy, dx - 1), e0, err(dy, dx + 1)))


def test_pan_moves_the_tfp_image_by_the_expected_amount():
    size = 64
    tex = _texture(3, 96, 96)
    vx, vy = 400.0, -200.0  # px/s
    scene = MotionScene(tex, size=(size, size), pan=(vx, vy), scale=1.0)
    T = 1000
    cap = simulate(scene, SimConfig.noiseless(n_ticks=T, cfa="none", seed=1))
    first = cap.count(0, 200).astype(np.float64)
    last = cap.count(800, 1000).astype(np.float64)
    # window centres are 800 ticks = 0.04 s apart: the content moved by (dy, dx) = (−8, +16) px
    dy, dx = _motion_between(first, last)
    # both windows carry the same 4-px motion blur and 1/200 quantisation, so the texture
    # (σ = 2.5 px) registers to ~0.1 px; a 5 % speed error would be 0.8 px off
    assert dy == pytest.approx(-8.0, abs=0.25)
    assert dx == pytest.approx(16.0, abs=0.25)


def test_motion_scene_pan_is_an_exact_translation_at_whole_pixels():
    tex = _texture(4, 48, 48)
    scene = MotionScene(tex, size=(32, 32), pan=(100.0, 0.0), scale=1.0)
    f0 = scene.frame_at(0.0)
    f1 = scene.frame_at(0.05)  # 5 px to the right
    # bilinear sampling at whole-pixel offsets reproduces the samples (to float rounding)
    np.testing.assert_allclose(f1[:, 5:], f0[:, :-5], atol=1e-5)


def test_fan_turns_at_its_rate():
    fan = Fan(center=(16.0, 16.0), radius=14.0, rev_per_s=50.0, n_blades=3)
    scene = MotionScene(np.full((32, 32, 3), 0.5, np.float32), size=(32, 32), fans=[fan], scale=1.0)
    period = 1 / 50.0  # one revolution (the blades have different colours)
    f0, f_third, f_full = (scene.frame_at(t) for t in (0.0, period / 3, period))
    np.testing.assert_allclose(f_full, f0, atol=1e-4)  # atan2 rounding only
    # a third of a turn puts each blade where the next one was: same shapes, other colours
    assert np.abs(f_third - f0).mean() > 0.05
    np.testing.assert_allclose(f_third.sum(axis=2).mean(), f0.sum(axis=2).mean(), rtol=0.05)


def test_ground_truth_is_the_scene_at_the_tick_time():
    rng = np.random.default_rng(8)
    frames = rng.uniform(0, 1, (4, 8, 8, 3)).astype(np.float32)
    scene = ArrayScene(frames, fps=100.0)  # a key frame every 200 ticks
    cfg = SimConfig(n_ticks=600, gt_every=7, start_s=0.001)
    cap = simulate(scene, cfg)
    assert np.array_equal(cap.gt_ticks, np.arange(0, 600, 7))
    for tick in (0, 7, 150, 599):
        np.testing.assert_array_equal(cap.gt_at(tick), scene.frame_at(0.001 + tick / 20000))
    # the ground truth carries no colour cast
    np.testing.assert_array_equal(cap.gt_at(0), scene.frame_at(0.001))
    with pytest.raises(ParameterError, match="outside the simulated stream"):
        cap.gt_at(600)


def test_the_sensor_integrates_the_frame_of_each_tick():
    # black until tick 50, white from tick 50 (one key frame per tick): with rate 1 and no noise
    # every pixel fires first at tick 50 exactly, and then on every tick
    frames = np.zeros((100, 4, 8, 3), np.float32)
    frames[50:] = 1.0
    scene = ArrayScene(frames, fps=20000.0)
    cap = simulate(scene, SimConfig.noiseless(n_ticks=100, rate=1.0, spectral_gains=(1.0, 1.0, 1.0)))
    s = cap.read(0, 100)
    assert s[:50].max() == 0
    assert s[50:].min() == 1
    assert cap.gt_at(49).max() == 0.0 and cap.gt_at(50).min() == 1.0


def test_runs_longer_than_the_scene_are_refused():
    # 3 ms: ticks 0 … 60 (the last one at exactly 3 ms, where the last frame is still held)
    scene = ArrayScene(np.zeros((3, 8, 8, 3), np.float32), fps=1000.0)
    with pytest.raises(ParameterError, match="at most 61 ticks \\(--ticks 61"):
        simulate(scene, SimConfig(n_ticks=62))
    assert simulate(scene, SimConfig(n_ticks=61)).n_frames == 61


def test_progress_and_cancel():
    calls = []
    img = _random_image(9, 8, 8)
    simulate(StaticScene(img), SimConfig(n_ticks=50), progress=lambda a, b: calls.append((a, b)))
    assert calls[-1] == (50, 50)
    with pytest.raises(Cancelled):
        simulate(StaticScene(img), SimConfig(n_ticks=50), cancel=lambda: True)


def test_crop_and_resize_follow_the_config():
    img = _random_image(10, 20, 30)
    cap = simulate(StaticScene(img), SimConfig.noiseless(n_ticks=5, crop=[2, 3, 10, 12]))
    assert (cap.height, cap.width) == (10, 12)
    np.testing.assert_array_equal(cap.gt_at(0), img[2:12, 3:15])
    cap = simulate(StaticScene(img), SimConfig.noiseless(n_ticks=5, width=15, height=10))
    assert cap.gt_at(0).shape == (10, 15, 3)
    with pytest.raises(ParameterError, match="Crop"):
        simulate(StaticScene(img), SimConfig(n_ticks=5, crop=[15, 0, 10, 10]))


def test_in_memory_runs_have_a_size_limit():
    with pytest.raises(ParameterError, match="simulate_to_file"):
        simulate(StaticScene(_random_image(0, 8, 8)), SimConfig(n_ticks=1000), max_bytes=1000)
