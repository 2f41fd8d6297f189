"""Motion-aware temporal support (spikeview.guided.temporal): pooling, honesty of the data term, the plan,
chunk invariance, and the sequences benchmark's temporal error. Monochrome and Bayer throughout."""

from __future__ import annotations

import numpy as np
import pytest

from spikeview.guided.config import GuidedConfig
from spikeview.guided.observation import Observation, binomial_variance
from spikeview.guided.plan import make_plan
from spikeview.guided.temporal import TILE, pool_counts
from spikeview.io.source import ArraySource

CFAS = [None, "RGGB"]


def _texture(h=48, w=48, seed=0):
    rng = np.random.default_rng(seed)
    from scipy.ndimage import gaussian_filter

    t = gaussian_filter(rng.random((h + 64, w + 64)), 2.0)
    t = (t - t.min()) / (t.max() - t.min())
    return (0.1 + 0.8 * t).astype(np.float32)


def _spikes(rates: np.ndarray, seed=1) -> np.ndarray:
    """Bernoulli spikes with per-tick rates ``(T, H, W)``."""
    rng = np.random.default_rng(seed)
    return (rng.random(rates.shape) < rates).astype(np.uint8)


def _moving(ticks: int, speed: float, h=48, w=48, seed=0) -> np.ndarray:
    """Rates of a texture panned by ``speed`` pixels per tick along x (integer positions per tick)."""
    tex = _texture(h, w, seed)
    return np.stack([tex[8:8 + h, 8 + int(round(speed * t)):8 + int(round(speed * t)) + w] for t in range(ticks)]) * 0.6


@pytest.mark.parametrize("cfa", CFAS)
def test_static_scene_pools_every_neighbour_with_zero_shift(cfa):
    rates = np.repeat(_texture()[None, 8:56, 8:56] * 0.6, 90, axis=0)
    src = ArraySource(_spikes(rates), cfa=cfa)
    counts, pool = pool_counts(src, 40, 50, 3, cfa)
    assert pool.offsets == (-1, 1, -2, 2, -3, 3)
    assert pool.kind == "static" and pool.reason.startswith("static: ±3 windows")
    full = pool.dtau == 70
    assert full.mean() > 0.85
    assert all(not np.any(s) for s in pool.shifts.values())
    # a fully pooled photosite holds exactly the 70 ticks' spikes
    total = src.count(10, 80).astype(np.float32)
    np.testing.assert_array_equal(counts[full], total[full])
    obs = Observation.from_source(src, 45, 10, radius=3, eta=2.0)
    # Bernoulli spikes fire at random: the counts are the better estimate, so the interval rate stays out
    from spikeview.guided.temporal import interval_rates

    assert not np.isfinite(interval_rates(src, pool.support, cfa, counts / pool.dtau, min_ticks=70)).any()
    np.testing.assert_allclose(obs.y, counts / pool.dtau, rtol=1e-6)
    assert obs.mean_count() == pytest.approx(float(counts.mean()), rel=1e-5)
    assert "intervals" not in obs.pooling.reason
    plan = make_plan(obs, GuidedConfig(temporal_radius=3))
    assert plan.temporal == "static" and "static: ±3 windows" in str(plan)


@pytest.mark.parametrize("cfa", CFAS)
def test_moving_scene_is_aligned_by_its_motion(cfa):
    # the content moves left by 0.15 px per tick = 1.5 px per window: what sits at x in the centre
    # window sits at x - 1.5k in window k
    rates = _moving(90, 0.15)
    src = ArraySource(_spikes(rates), cfa=cfa)
    _, pool = pool_counts(src, 40, 50, 2, cfa)
    for k in (-2, -1, 1, 2):
        sh = pool.shifts[k][pool.accepted[k]]
        assert len(sh) >= 0.5 * pool.shifts[k][..., 0].size
        dx = np.median(sh[:, 1])
        assert abs(dx + 1.5 * k) <= 2, (k, dx)  # shifts are whole 2×2 super-pixels
        assert np.all(np.abs(sh[:, 0]) <= 2)
    assert pool.kind in ("aligned", "mixed")


@pytest.mark.parametrize("cfa", CFAS)
def test_a_change_in_the_centre_window_is_not_ghosted(cfa):
    """A square that appears only in the centre window (a flash): its photosites keep their own window."""
    rates = np.repeat(_texture(64, 64)[None, 8:72, 8:72] * 0.3, 70, axis=0)
    rates[30:40, 16:32, 16:32] = 0.95
    src = ArraySource(_spikes(rates), cfa=cfa)
    _, pool = pool_counts(src, 30, 40, 3, cfa)
    inner = pool.dtau[16:32, 16:32]
    assert np.all(inner == 10), "the flash must not be averaged with the windows around it"
    far = pool.dtau[48:, :].ravel().tolist() + pool.dtau[:, 48:].ravel().tolist()  # tiles away from the flash
    assert np.mean(far) >= 55  # 4.5 of the 6 neighbours on average (the per-photosite test rejects a few by chance)


@pytest.mark.parametrize("cfa", CFAS)
def test_capture_too_short_and_radius_zero_say_why(cfa):
    from spikeview.guided.knobs import knob_status

    src = ArraySource(_spikes(np.full((10, 16, 16), 0.5)), cfa=cfa)
    obs = Observation.from_source(src, 5, 10, radius=2, eta=2.0)
    assert obs.dtau is None and obs.pooling.kind == "unavailable"
    plan = make_plan(obs, GuidedConfig(temporal_radius=2))
    assert plan.temporal == "off" and "the capture holds 10 ticks" in plan.reasons["temporal"]
    why = knob_status(GuidedConfig(temporal_radius=2), plan)["guided.temporal_radius"]
    assert why is not None and "10 ticks" in why
    long = ArraySource(_spikes(np.full((40, 16, 16), 0.5)), cfa=cfa)
    obs = Observation.from_source(long, 15, 10, radius=2, eta=2.0)
    assert obs.pooling.offsets == (-1, 1, 2)  # only whole windows inside the capture
    assert knob_status(GuidedConfig(temporal_radius=2), make_plan(obs, GuidedConfig(temporal_radius=2)))["guided.temporal_radius"] is None
    plain = make_plan(Observation.from_source(long, 15, 10, eta=2.0, radius=0), GuidedConfig())
    assert plain.temporal == "off" and "temporal_radius = 0" in plain.reasons["temporal"]


@pytest.mark.parametrize("cfa", CFAS)
def test_data_term_uses_the_effective_window(cfa):
    """Noise weights from Δτ_eff per photosite; Q rounds to the pooled step, 1/Δτ_eff (the mean Δτ_eff: a pooled value
    is the aligned windows' spikes over Δτ_eff ticks)."""
    import torch

    from spikeview.guided.sampler import GuidedSampler
    from spikeview.ops.quantise import soft_quantise

    rng = np.random.default_rng(3)
    dtau = np.where(rng.random((16, 16)) < 0.5, 10.0, 30.0).astype(np.float32)
    y = (rng.integers(0, 10, (16, 16)) / dtau).astype(np.float32)
    obs = Observation(y, cfa, 10, dtau=dtau)
    v = binomial_variance(y, dtau)
    for n in (10.0, 30.0):
        m = dtau == n
        np.testing.assert_allclose(v[m], binomial_variance(y, int(n))[m], rtol=1e-5)
    assert obs.variance().shape == (16, 16)
    assert float(obs.variance()[dtau == 30.0].mean()) < float(obs.variance()[dtau == 10.0].mean())
    plan = make_plan(obs, GuidedConfig(quantise=True))
    fm = GuidedSampler.forward_model(obs, plan, GuidedConfig(quantise=True, k=1000.0))
    # half the photosites pooled 30 ticks, half 10: Q on the 1/Δτ_eff grid of their mean (~20 ticks), k scaled with it
    # (no dark rate measured: floor 0), in monochrome too
    q = obs.quantise_window()
    assert 15 <= q <= 25
    x = torch.rand(1, 1, 16, 16)
    np.testing.assert_allclose(fm.quantise(x).numpy(), soft_quantise(x, q, 1000.0 * q / 10).numpy(), atol=1e-6)
    assert fm(torch.rand(1, 1 if cfa is None else 3, 16, 16)).shape == (1, 1, 16, 16)
    with pytest.raises(Exception, match="dtau"):
        Observation(y, cfa, 10, dtau=np.full((16, 16), 5.0, dtype=np.float32))


@pytest.mark.parametrize("cfa", CFAS)
def test_q_is_decided_from_the_pooled_count(cfa):
    """A dim static colour scene (~0.5 spikes per photosite per window) pools several over ±3 windows: its value is a
    count of ~3.5 spikes over Δτ_eff, not a small integer, and Q is off, while its single window alone has Q on; a
    darker one (~0.1 a window, ~0.7 pooled) keeps Q on, on its pooled grid. The reason gives the pooled count.
    Monochrome alike (its black corner: no dark rate in the rates)."""
    from spikeview.guided.plan import Q_COUNT

    for rate, on in ((0.05, False), (0.01, True)):
        rates = np.full((90, 32, 32), rate)
        rates[:, :16, :16] = 0.0  # a black corner: no dark rate in the rates (Observation.quantise_window)
        src = ArraySource(_spikes(rates, seed=4), cfa=cfa)
        pooled = Observation.from_source(src, 45, 10, radius=3, eta=2.0)
        alone = Observation.from_source(src, 45, 10, eta=2.0, radius=0)
        assert pooled.mean_count() > 3 * pooled.window_count()  # most photosites pooled several windows
        assert alone.window_count() == pytest.approx(alone.mean_count())
        cfg = GuidedConfig(diffusion="always")
        plan, single = make_plan(pooled, cfg), make_plan(alone, cfg)
        assert plan.quantise is on and single.quantise is True
        assert (pooled.quantise_count() < Q_COUNT) is on
        assert f"{pooled.mean_count():.2f} spikes per photosite pooled over the aligned windows" in plan.reasons["quantise"]


@pytest.mark.parametrize("cfa", CFAS)
def test_sequence_frames_do_not_depend_on_the_chunking(cfa):
    """reconstruct_windows over a range equals the same windows computed chunk by chunk (each chunk
    starting at a keyframe) and the single-frame path; neighbours are read across chunk borders."""
    from spikeview.cluster._compute import compute_chunk, prepare_state
    from spikeview.guided.sampler import GuidedSampler
    from spikeview.pipeline import KEYFRAME, reconstruct_windows
    from spikeview.recipe import Recipe

    rates = _moving(200, 0.05, 32, 32)
    src = ArraySource(_spikes(rates), cfa=cfa)
    recipe = Recipe().with_values({"run.method": "guided", "guided.steps": 1, "guided.temporal_radius": 2})
    data = recipe.to_dict()
    centres = list(range(35, 165, 10))[:KEYFRAME] + []
    state = prepare_state(src, data)
    smp = GuidedSampler(recipe.guided, prior=_blur_prior(1 if cfa is None else 3))
    whole = np.stack(list(reconstruct_windows(src, centres, recipe, state, sampler=smp)))
    # chunks of 4 windows, each the start of its own chain (as the batch path splits at keyframes)
    parts = [compute_chunk(src, centres[i:i + 4], data, state, sampler=smp) for i in range(0, len(centres), 4)]
    parts = [np.asarray(p).reshape((len(p),) + whole.shape[1:]) for p in parts]  # the store keeps a channel axis
    np.testing.assert_array_equal(parts[0], whole[:4])
    alone = np.stack(list(reconstruct_windows(src, [centres[4]], recipe, state, sampler=smp)))[0]
    np.testing.assert_array_equal(alone, parts[1][0])  # --at reads its own neighbours, across the chunk border
    # every chunk equals the same windows run as one sequence (its neighbours read outside the chunk)
    for i, p in zip(range(0, len(centres), 4), parts):
        ref = np.stack(list(reconstruct_windows(src, centres[i:i + 4], recipe, state, sampler=smp)))
        np.testing.assert_array_equal(p, ref)
    # and the pooling did use windows outside each chunk
    obs = Observation.from_source(src, centres[4], 10, radius=2, eta=2.0)
    assert obs.pooling.offsets == (-1, 1, -2, 2) and obs.dtau is not None and obs.dtau.max() > 10


def _blur_prior(channels):
    """A quick, deterministic stand-in prior (3×3 mean)."""
    from spikeview.guided.priors.base import DenoiserPrior

    class Blur(DenoiserPrior):
        def __init__(self):
            self.channels = channels
            self.sigma_max = 75 / 255

        def denoise(self, x, sigma):
            import torch.nn.functional as F

            return F.avg_pool2d(F.pad(x, (1, 1, 1, 1), mode="replicate"), 3, stride=1)

    return Blur()


@pytest.mark.parametrize("cfa", CFAS)
def test_region_of_interest_crops_the_pooled_observation(cfa):
    """The ROI path (the app's Run on a region) crops Δτ_eff with the counts; the plan still says what was pooled."""
    from spikeview.guided.sampler import GuidedSampler
    from spikeview.guided.window import crop_to_roi as _crop_to_roi
    from spikeview.pipeline import prepare_sequence, reconstruct_windows
    from spikeview.recipe import Recipe

    src = ArraySource(_spikes(np.repeat(_texture(32, 32)[None, 8:40, 8:40] * 0.5, 80, axis=0)), cfa=cfa)
    obs = Observation.from_source(src, 45, 10, radius=3, eta=2.0)
    sub = _crop_to_roi(obs, (5, 7, 16, 12))
    assert sub.shape == (13, 17) and sub.dtau.shape == (13, 17)  # origin rounded down to even pixels: (6, 4)
    np.testing.assert_array_equal(sub.dtau, obs.dtau[6:19, 4:21])
    np.testing.assert_array_equal(sub.y, obs.y[6:19, 4:21])
    whole = make_plan(obs, GuidedConfig(temporal_radius=3))
    assert whole.temporal != "off" and make_plan(sub, GuidedConfig(temporal_radius=3)).temporal == whole.temporal
    recipe = Recipe().with_values({"run.method": "guided", "guided.steps": 1})
    assert recipe.guided.temporal_radius == 3  # the default pools
    state = prepare_sequence(src, recipe)
    smp = GuidedSampler(recipe.guided, prior=_blur_prior(1 if cfa is None else 3))
    frames = list(reconstruct_windows(src, [45, 55], recipe, state, roi=(4, 6, 16, 16), sampler=smp))
    assert frames[0].shape[:2] == (16, 16) and np.isfinite(frames[1]).all()


def test_temporal_error_measures_flicker():
    from spikeview.bench.temporal import temporal_error

    g = [np.full((8, 8), 0.5, dtype=np.float32)] * 4
    assert temporal_error(g, g) == pytest.approx(0.0, abs=1e-9)
    flick = [g[0] + (0.02 if i % 2 else 0.0) for i in range(4)]
    # every difference is ±0.02 (gain fitted over the sequence ~ 1/1.02 at most moves it slightly)
    assert 4.0 < temporal_error(flick, g) < 5.5
    rgb = [np.full((8, 8, 3), 0.5, dtype=np.float32)] * 3
    assert temporal_error(rgb, rgb) == pytest.approx(0.0, abs=1e-9)
    # one gain per channel for the whole sequence: a colour cast of the output costs nothing, a gain
    # per frame or per column would hide a flicker (gray) and one gain for all channels would not fit
    rng = np.random.default_rng(0)
    moving = [rng.random((8, 8, 3)).astype(np.float32) for _ in range(4)]
    cast = [m * np.array([0.5, 1.0, 2.0], np.float32) for m in moving]
    assert temporal_error(cast, moving) == pytest.approx(0.0, abs=1e-6)
    gray = [m[..., 1] for m in moving]
    ramp = [m * np.linspace(0.5, 1.5, 8, dtype=np.float32)[None, :] for m in gray]  # not one gain: it counts
    assert temporal_error(ramp, gray) > 10.0
    # moved=(dy, dx): errors carried along with the content; a fixed error pattern moved by one pixel
    # gives the RMS of its own difference, not 0
    err = rng.random((8, 8)).astype(np.float32) * 0.1
    still = [np.full((8, 8), 0.5, np.float32)] * 3
    stuck = [g + err for g in still]
    assert temporal_error(stuck, still) == pytest.approx(0.0, abs=1e-3)
    carried = [g + np.roll(err, (i, 2 * i), axis=(0, 1)) for i, g in enumerate(still)]
    assert temporal_error(carried, still, moved=(1, 2)) == pytest.approx(0.0, abs=0.3)
    assert temporal_error(stuck, still, moved=(1, 2)) > 5.0


@pytest.mark.parametrize("cfa", CFAS)
def test_library_reconstruct_frame_pools_as_its_config_says(cfa):
    """``guided.reconstruct_frame`` (the library's one-frame call) reads the neighbours ``temporal_radius`` asks for."""
    from spikeview.guided.sampler import GuidedSampler
    from spikeview.guided.video import reconstruct_frame, resolve_alpha

    rates = np.repeat(_texture()[None, 8:56, 8:56] * 0.6, 90, axis=0)
    src = ArraySource(_spikes(rates), cfa=cfa)
    p = GuidedConfig(temporal_radius=3)
    a = resolve_alpha(src, p, None)
    got = np.asarray(reconstruct_frame(src, 45, p))
    want = np.asarray(GuidedSampler(p).run(Observation.from_source(src, 45, p.window, alpha=a, eta=p.eta, radius=3), p))
    np.testing.assert_array_equal(got, want)
    single = np.asarray(reconstruct_frame(src, 45, p.replace(temporal_radius=0)))
    assert np.abs(single - got).mean() > 1 / 255


@pytest.mark.parametrize("cfa", CFAS)
def test_the_interval_rate_beats_the_count_on_an_evenly_firing_pixel_and_keeps_a_random_ones_level(cfa):
    """Integrate-and-fire photosites of a static scene fire evenly: the rate from their spikes' intervals over the
    pooled support is several times closer to the truth than their count (which loses up to a spike to the phase
    at each end), at the counts' level; random (Bernoulli) firing keeps its counts (the intervals vary: no interval
    rate), and the observation says which it took."""
    from spikeview.guided.temporal import interval_rates

    rng = np.random.default_rng(5)
    truth = np.clip(_texture()[8:56, 8:56] * 0.08, 0.01, None)  # 0.01-0.08 spikes a tick: a dark scene
    phase = rng.random(truth.shape)
    t = np.arange(200)[:, None, None]
    even = (np.floor(phase + truth * (t + 1)) - np.floor(phase + truth * t)).astype(np.uint8)  # integrate and fire
    random = _spikes(np.repeat(truth[None], 200, axis=0), seed=6)
    for spikes, better in ((even, True), (random, False)):
        src = ArraySource(spikes, cfa=cfa)
        counts, pool = pool_counts(src, 95, 105, 3, cfa)
        rate_c = counts / pool.dtau
        yi = interval_rates(src, pool.support, cfa, rate_c, min_ticks=70)
        ok = np.isfinite(yi)
        obs = Observation.from_source(src, 100, 10, radius=3, eta=2.0)
        if not better:
            assert not ok.any() and "intervals" not in obs.pooling.reason
            continue
        assert ok.mean() > 0.7 and "intervals between their spikes" in obs.pooling.reason  # pooled at rest, 2+ spikes
        err_i = float(np.abs(yi[ok] - truth[ok]).mean())
        err_c = float(np.abs(rate_c[ok] - truth[ok]).mean())
        if better:
            assert err_i < 0.5 * err_c, (err_i, err_c)
        y = np.where(ok, yi, rate_c)  # as the observation takes it
        assert float(y.mean()) == pytest.approx(float(rate_c.mean()), rel=1e-4)  # the counts' level is kept
        assert float(y.mean()) == pytest.approx(float(truth.mean()), rel=0.05)


def test_frame_drift_measures_a_sub_pixel_shift_of_the_whole_frame_and_refuses_noise():
    from scipy.ndimage import shift as nd_shift

    from spikeview.guided.temporal import frame_drift

    rng = np.random.default_rng(2)
    tex = _texture(96, 96, 3)
    for dy, dx in ((2.5, 0.0), (-1.25, 3.0), (0.0, 0.0)):
        moved = nd_shift(tex, (dy, dx), order=1, mode="nearest")
        a = rng.poisson(tex * 20.0).astype(float)  # sums of many windows (a few spikes each)
        b = rng.poisson(np.clip(moved, 0, None) * 20.0).astype(float)
        d = frame_drift(a, b)
        assert d is not None and d[0] == pytest.approx(dy, abs=0.3) and d[1] == pytest.approx(dx, abs=0.3), (dy, dx, d)
    assert frame_drift(rng.poisson(1.0, (96, 96)).astype(float), rng.poisson(1.0, (96, 96)).astype(float)) is None


@pytest.mark.parametrize("own_share", [0.0, 0.03])
def test_static_sentence_says_the_share_that_pooled_at_least_one_neighbour(own_share):
    """A static pooling that took every neighbour on 92 % of photosites says on what share it took at least one (the
    issue's "pooled"): those on their own window only are left out of that share, and the clause is absent when
    (nearly) every photosite took every neighbour."""
    from spikeview.guided.temporal import Pooling, describe

    h = w = 100
    dtau = np.full((h, w), 70.0, np.float32)
    flat = dtau.ravel()
    n_own = int(own_share * h * w)
    flat[:n_own] = 10.0                      # own window only
    flat[n_own:n_own + 800 - n_own] = 40.0   # some neighbours: 8 % short of the full support in all
    offsets = (-1, 1, -2, 2, -3, 3)
    tiles = np.zeros((2, 2, 2), int)
    pool = Pooling(radius=3, window=10, offsets=offsets, dtau=dtau, shifts={k: tiles for k in offsets},
                   accepted={k: np.ones((2, 2), bool) for k in offsets})
    kind, sentence = describe(pool)
    assert kind == "static" and "pooled on 92% of photosites" in sentence
    assert f"at least one neighbour on {100 - round(100 * own_share)}%" in sentence
    pool.dtau = np.full((h, w), 70.0, np.float32)
    assert "at least one neighbour" not in describe(pool)[1]


@pytest.mark.parametrize("cfa", CFAS)
@pytest.mark.parametrize("axis", [0, 1])
def test_a_panning_frame_says_its_measured_velocity(cfa, axis):
    """The plan's pan velocity is the whole frame's measured shift between the farthest neighbours, not the search's
    coarse grid (a 0.36-photosite-a-window drift was said as "about +0.67"): vertical and horizontal, both CFAs."""
    from scipy.ndimage import shift as nd_shift

    rng = np.random.default_rng(4)
    from scipy.ndimage import gaussian_filter

    tex = gaussian_filter(rng.random((160, 160)), 2.0)
    tex = 0.1 + 0.8 * (tex - tex.min()) / (tex.max() - tex.min())
    speed = 0.05  # photosites a tick: 0.5 a 10-tick window
    rates = np.empty((90, 96, 96), np.float32)
    for t in range(90):
        move = [0.0, 0.0]
        move[axis] = -speed * t  # content moves towards smaller indices: a velocity of −0.5
        rates[t] = nd_shift(tex, move, order=1)[32:128, 32:128] * 0.6
    src = ArraySource(_spikes(rates, seed=2), cfa=cfa)
    _, pool = pool_counts(src, 40, 50, 3, cfa)
    assert "the frame pans (" in pool.reason
    said = pool.reason.split("the frame pans (")[1].split(" photosites")[0]
    v = [float(x) for x in said.split(", ")]
    assert v[axis] == pytest.approx(-0.5, abs=0.08) and abs(v[1 - axis]) < 0.08, pool.reason


@pytest.mark.parametrize("cfa", CFAS)
def test_a_lone_false_alarm_pools_with_its_neighbours_and_a_patch_does_not(cfa):
    """``_lone``: a photosite (or a pair) failing the per-photosite test among same-colour neighbours that passed it is
    rescued; a 3×3 same-colour patch is not (motion moves a patch); the frame's border counts only the neighbours it
    has; numpy and torch agree."""
    import torch

    from spikeview.guided.temporal import _lone

    step = 1 if cfa is None else 2
    h = w = 12 * step
    rejected = np.zeros((h, w), bool)
    rejected[4 * step, 4 * step] = True  # alone
    rejected[0, 9 * step] = True  # alone on the border
    rejected[9 * step, 2 * step] = rejected[9 * step, 3 * step] = True  # a pair
    rejected[5 * step:8 * step:step, 8 * step:11 * step:step] = True  # a 3×3 same-colour patch
    accepted = ~rejected
    got = _lone(rejected, accepted, cfa)
    want = rejected.copy()
    want[5 * step:8 * step:step, 8 * step:11 * step:step] = False
    np.testing.assert_array_equal(got, want)
    on_torch = _lone(torch.from_numpy(rejected), torch.from_numpy(accepted), cfa).numpy()
    np.testing.assert_array_equal(on_torch, got)
    # a rejected photosite next to an unaccepted one that is not rejected (a tile left out): not a false alarm's pair
    accepted2 = accepted.copy()
    accepted2[4 * step, 5 * step] = accepted2[5 * step, 5 * step] = False
    assert not _lone(rejected, accepted2, cfa)[4 * step, 4 * step]
    # a frame too small for neighbours, or a photosite none of whose neighbours passed: nothing to rescue it by
    tiny = np.ones((2 * step, 2 * step) if cfa else (1, 1), bool)
    assert not _lone(tiny, ~tiny, cfa).any()
    assert not _lone(np.ones((step, 5 * step), bool), np.zeros((step, 5 * step), bool), cfa).any()


@pytest.mark.parametrize("cfa", CFAS)
def test_a_regular_integrate_and_fire_dark_capture_leaves_no_unpooled_photosite(cfa):
    """A static scene from a noise-free integrate-and-fire simulator (as the ecosystem's are: random phase, no noise),
    0.04 spikes per tick: a photosite's 10-tick counts swing regularly, so a 3×3 sum can go from empty to full between
    two windows. Under 1 % of the static scene's photosites stop short of ±3 windows (before: 2.3 % mono, 2.8 %
    Bayer, some of them on their own 10-tick window, 0 or 0.1: a black or white dot in the guided frame; what is left
    is runs of 3 or more along the border, where the 3×3 sums repeat the edge)."""
    h = w = 64
    rate = 0.03 + 0.02 * _texture(h, w, seed=3)[8:8 + h, 8:8 + w]
    rng = np.random.default_rng(5)
    acc = rng.random((h, w))
    spikes = np.empty((400, h, w), np.uint8)
    for t in range(400):
        acc += rate
        spikes[t] = acc >= 1.0
        acc[spikes[t] == 1] -= 1.0
    src = ArraySource(spikes, cfa=cfa)
    _, pool = pool_counts(src, 195, 205, 3, cfa)
    assert pool.kind == "static"
    assert (pool.dtau < 70).mean() < 0.01, f"{int((pool.dtau < 70).sum())} photosites kept fewer than ±3 windows"


@pytest.mark.parametrize("cfa", CFAS)
def test_a_bright_regular_static_capture_is_held_at_rest(cfa):
    """A real sensor's bright pixels fire almost regularly (a real static capture: 2.2 spikes a 10-tick window, its
    count variance 0.10x a binomial's): a photosite's adjacent windows anticorrelate (2, 3, 2, 3 …), so on flat content
    another photosite at a shift could match better than the same one at rest, and a third of a static scene's tiles
    were 'aligned' by up to 4 px (pooled ±3 on 87 %; the guided frame 3.7 dB below the held one). A bright tile whose
    zero shift passes the tile test is held at rest: the scene is static again, ±3 pooled nearly everywhere."""
    import skimage.data
    from skimage.transform import resize

    h = w = 64
    rate = 0.05 + 0.3 * resize(skimage.data.camera() / 255.0, (h, w), anti_aliasing=True)
    rng = np.random.default_rng(6)
    acc = rng.random((h, w))
    spikes = np.empty((200, h, w), np.uint8)
    for t in range(200):
        acc += rate * (1 + 0.05 * rng.standard_normal((h, w)))
        spikes[t] = acc >= 1.0
        acc[spikes[t] == 1] -= 1.0
    counts = spikes[:190].reshape(19, 10, h, w).sum(axis=1)
    p = counts.mean(axis=0) / 10
    assert counts.var(axis=0).mean() < 0.2 * (10 * p * (1 - p)).mean()  # regular, as the real capture
    _, pool = pool_counts(ArraySource(spikes, cfa=cfa), 95, 105, 3, cfa)
    assert pool.kind == "static", pool.reason
    assert all(not np.any(s) for s in pool.shifts.values())
    assert (pool.dtau >= 70).mean() > 0.95, (pool.dtau >= 70).mean()


@pytest.mark.parametrize("cfa", CFAS)
def test_a_dim_pan_glides_instead_of_pooling_the_scene_away(cfa, monkeypatch):
    """A dim capture (0.03 spikes per tick) that pans a photosite a window: no tile shows the pan above its noise, so
    its windows were pooled at rest to ±16 and the scene smeared over 33 photosites (the guided frame's detail 0.10
    against TFI's 0.32). The whole frame's velocity is measured (within 0.1 photosite a window), every neighbouring
    window is moved back by it before pooling, and the pooled frame keeps far more of the truth's detail than the
    same pooling at rest; the static scene at the same light does not glide."""
    import skimage.data
    from scipy.ndimage import gaussian_filter
    from skimage.transform import resize

    import spikeview.guided.temporal as T
    from spikeview.metrics import detail_kept
    from spikeview.sim import MotionScene, SimConfig, simulate

    img = resize(skimage.data.camera().astype(np.float32) / 255.0, (256, 256), anti_aliasing=True)
    img = np.repeat(img[..., None], 3, axis=-1).astype(np.float32)
    n = 160

    def capture(pan):
        cfg = SimConfig(n_ticks=400, seed=2, cfa=cfa or "none", rate=0.03, gt_every=50)
        return simulate(MotionScene(img, size=(n, n), pan=pan, srgb=False), cfg)

    def pooled(src):
        counts, pool = T.pool_counts(src, 195, 205, 3, cfa)
        return counts / pool.dtau, pool

    moving = capture((2000.0, 0.0))  # px per second at 20 kHz: a photosite per 10-tick window, along x
    truth = moving.gt_at(200).astype(np.float64).mean(axis=-1)
    rate, pool = pooled(moving)
    assert pool.glide is not None and pool.kind == "aligned", pool.reason
    assert abs(pool.glide[0]) < 0.1 and pool.glide[1] == pytest.approx(1.0, abs=0.1), pool.glide
    assert "glides" in pool.reason
    lum = rate if cfa is None else gaussian_filter(rate, 1.0)  # a mosaic's detail seen through its colour planes
    with monkeypatch.context() as m:
        m.setattr(T, "GLIDE_REST", np.inf)  # the same pooling at rest
        still_rate, still_pool = pooled(moving)
    assert still_pool.glide is None
    lum_still = still_rate if cfa is None else gaussian_filter(still_rate, 1.0)
    assert detail_kept(lum, truth) > detail_kept(lum_still, truth) + 0.1, (detail_kept(lum, truth),
                                                                          detail_kept(lum_still, truth))
    _, static = pooled(capture((0.0, 0.0)))
    assert static.glide is None and static.kind == "static", static.reason
