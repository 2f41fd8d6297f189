"""Each rule of the pooling, the per-tile plan and the plan's Q and reuse decisions, held by a test that fails when
the rule is broken (issue 25, item 6: seven one-line bugs passed the whole suite when planted alone). Synthetic
integrate-and-fire captures with known motion, vertical and horizontal, monochrome and Bayer."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.ndimage import gaussian_filter

from spikeview.guided import temporal
from spikeview.io.source import ArraySource

H = W = 64
WINDOW = 10


def _texture(seed: int = 0, size: int = 160, smooth: float = 2.0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    t = gaussian_filter(rng.random((size, size)), smooth)
    t = (t - t.min()) / (t.max() - t.min())
    return (0.15 + 0.75 * t).astype(np.float64)  # rates 0.15–0.9 spikes per tick: strong, textured


def _capture(cfa: str | None, dy: int = 0, dx: int = 0, windows: int = 9, swap: tuple[int, slice, slice] | None = None,
             seed: int = 0, smooth: float = 2.0, change: tuple[int, slice, slice, float] | None = None) -> ArraySource:
    """Spikes (Bernoulli per tick: binomial counts, the plan's noise model) of a texture moving (dy, dx) photosites
    per 10-tick window (integer steps at window edges); ``swap = (window, rows, cols)``: that window's region shows
    the scene's negative (something only it sees); ``change = (window, rows, cols, factor)``: in
    that window only, the region's rates are multiplied by ``factor`` (a flicker)."""
    tex = _texture(seed, smooth=smooth)
    y0 = x0 = 48
    rng = np.random.default_rng(seed + 1)
    out = np.zeros((windows * WINDOW, H, W), np.uint8)
    for k in range(windows):
        r = tex[y0 - k * dy:y0 - k * dy + H, x0 - k * dx:x0 - k * dx + W].copy()  # content moves (+dy, +dx) a window
        if swap is not None and swap[0] == k:
            r[swap[1], swap[2]] = 1.05 - r[swap[1], swap[2]]  # the negative: unlike the scene at every photosite
        if change is not None and k == change[0]:
            r[change[1], change[2]] = np.clip(r[change[1], change[2]] * change[3], 0.0, 1.0)
        for t in range(WINDOW):
            out[k * WINDOW + t] = rng.random((H, W)) < r
    return ArraySource(out, cfa=cfa)


CFAS = pytest.mark.parametrize("cfa", ["RGGB", None], ids=["bayer", "mono"])


def _pool(src, centre_window: int = 4, radius: int = 3):
    a = centre_window * WINDOW
    return temporal.pool_counts(src, a, a + WINDOW, radius, src.cfa)


@CFAS
@pytest.mark.parametrize("dy,dx", [(2, 0), (0, 2), (-2, 0)], ids=["down", "right", "up"])
def test_moving_content_is_aligned_the_right_way_and_pooled(cfa, dy, dx):
    """Neighbour k is read at +k·v: content at (y, x) of the centre window is at (y + k·dy, x + k·dx) in window k
    (reading it at −dy reverses vertical alignment: nothing matches, nothing is pooled)."""
    src = _capture(cfa, dy, dx, smooth=0.7)
    _, pool = _pool(src, radius=1)
    for k in (-1, 1):
        inner = pool.shifts[k][1:-1, 1:-1]
        assert (inner[..., 0] == k * dy).mean() > 0.8 and (inner[..., 1] == k * dx).mean() > 0.8, (k, inner[..., :].tolist())
    pooled = pool.dtau / WINDOW - 1
    assert (pooled[8:-8, 8:-8] >= 1.5).mean() > 0.8  # both neighbours taken inside the frame
    # and what was taken is the same content: the pooled rate's error against the truth is that of three windows
    # (1/√3 ≈ 0.58 of the own window's), not of misaligned ones (a read at −dy: 0.83–0.85)
    total, pool = _pool(src, radius=1)
    truth = _texture(0, smooth=0.7)[48 - 4 * dy:48 - 4 * dy + H, 48 - 4 * dx:48 - 4 * dx + W]
    own = src.read(4 * WINDOW, 5 * WINDOW).sum(axis=0) / WINDOW
    inner = (slice(8, -8), slice(8, -8))
    err = np.sqrt(np.mean(((total / pool.dtau) - truth)[inner] ** 2)) / np.sqrt(np.mean((own - truth)[inner] ** 2))
    assert err < 0.68, err


@CFAS
def test_no_neighbour_is_pooled_past_the_displacement_cap(cfa):
    """At 3 photosites a window, windows ±1 (3 px) are within MAX_SHIFT (4) and pooled, windows ±2 (6 px) and ±3
    (9 px) are not, however well they match."""
    src = _capture(cfa, 3, 0)
    _, pool = _pool(src, radius=3)
    assert temporal.MAX_SHIFT == 4
    for k in (-2, 2, -3, 3):
        assert not pool.accepted[k].any(), k
    pooled = pool.dtau / WINDOW - 1
    assert pooled.max() <= 2 and (pooled[8:-8, 8:-8] == 2).mean() > 0.5


@CFAS
def test_a_photosite_takes_window_k_only_with_every_nearer_one(cfa):
    """Window +1 shows something else over two tiles' width (a passing object): those photosites take neither +1
    nor +2, +3 (which match again), while the windows on the other side are pooled as usual."""
    src = _capture(cfa, 0, 0, swap=(5, slice(16, 48), slice(16, 48)))
    _, pool = _pool(src, centre_window=4, radius=3)
    pooled = pool.dtau / WINDOW - 1
    inside = pooled[18:46, 18:46]
    outside = np.concatenate([pooled[2:12, 2:-2].ravel(), pooled[-12:-2, 2:-2].ravel()])
    assert (inside <= 3).mean() > 0.95, np.unique(inside, return_counts=True)  # the −1, −2, −3 side only
    assert (outside == 6).mean() > 0.8  # a static scene elsewhere: all six neighbours
    assert (inside == 3).mean() > 0.5  # and that side is taken


def _tile_obs(cfa: str | None):
    """A 256×128 observation: the left half pooled over 70 ticks (σ ≈ 15/255, quiet against a 25/255 target), the
    right half its own 10-tick window (σ ≈ 40/255)."""
    from spikeview.guided.observation import Observation

    rng = np.random.default_rng(3)
    h, w = 128, 256
    left = np.arange(w)[None, :] < w // 2
    dtau = np.where(left, 70.0, 10.0).astype(np.float32) * np.ones((h, 1), np.float32)
    y = (rng.binomial(dtau.astype(int), 0.5) / dtau).astype(np.float32)
    return Observation(y, cfa, 10, None, 2.0, (0, 10), 5, None, dtau)


@CFAS
def test_quiet_tiles_are_skipped_under_auto_and_never_under_always(cfa):
    from spikeview.guided.config import GuidedConfig
    from spikeview.guided.plan import make_plan

    obs = _tile_obs(cfa)
    target = (25 if cfa is None else 18) / 255  # between the quiet half's σ and the frame's (demosaicking lowers a Bayer σ)
    auto = make_plan(obs, GuidedConfig(tile=64, noise_target=target))
    assert auto.tile_map is not None and auto.tile_map.counts()["skipped"] > 0, auto.reasons
    always = make_plan(obs, GuidedConfig(tile=64, noise_target=target, diffusion="always"))
    assert always.tile_map is not None and always.tile_map.counts()["skipped"] == 0


@CFAS
def test_a_short_tile_joins_at_the_first_step_low_enough(cfa):
    from spikeview.guided import tiles
    from spikeview.guided.config import GuidedConfig
    from spikeview.guided.plan import make_plan

    p = GuidedConfig(tile=64, steps=8, noise_target=1 / 255)
    plan = make_plan(_tile_obs(cfa), p)
    tm = plan.tile_map
    assert tm is not None
    sched, _, _ = tiles.frame_ladder(plan, p, 3 if plan.mosaic else 1, 75 / 255)
    levels = sched.sigmas[:p.steps].max(axis=1)
    short = [t for t in tm.tiles if t.kind == "short"] or [t for t in tm.tiles if 0 < t.join < p.steps]
    probe = tiles.plan_tiles(_tile_obs(cfa), plan, p.replace(steps=8))
    checked = 0
    for t in probe.tiles:
        if t.kind == "skipped":
            continue
        told = t.sigma * p.sigma_scale
        ok = np.flatnonzero(levels <= tiles.JOIN_FACTOR * told)
        if t.kind == "short":
            assert t.join == int(ok[0]), (t.join, ok.tolist())
            checked += 1
    assert checked > 0 or not short, "no short tile to check"


def _q_obs():
    from spikeview.guided.observation import Observation

    rng = np.random.default_rng(0)
    y = rng.binomial(10, 0.6, size=(32, 32)).astype(np.float32) / 10.0  # 6 spikes per window: Q off for HQS
    return Observation(y, "RGGB", 10, np.array([1.0, 1.0, 1.0]), 2.0, (0, 10), 5)


@pytest.mark.parametrize("guidance,prior,want", [("hqs", "ffdnet", False), ("dps", "ffdnet", True), ("dps", "sd", True)])
def test_q_is_on_for_dps_or_the_sd_prior(guidance, prior, want):
    from spikeview.guided.config import GuidedConfig
    from spikeview.guided.plan import make_plan

    p = GuidedConfig(guidance=guidance, prior=prior, model_path="x" if prior == "sd" else None)
    assert make_plan(_q_obs(), p).quantise is want


@CFAS
def test_the_reuse_test_compares_the_own_windows_of_a_pooled_observation(cfa):
    """A static scene, unchanged from the window before (nothing flagged), and one whose left half flickers 25 %
    brighter in this window only: the own window differs from the one before there. The pooled window (its
    neighbours, which match within their noise, show the steady scene) dilutes that change about sevenfold: compared
    instead of the own window, it would be missed."""
    from spikeview.guided.config import GuidedConfig
    from spikeview.guided.observation import Observation
    from spikeview.guided.plan import changed_blocks

    p = GuidedConfig()
    alpha = None if cfa is None else [1.0, 1.0, 1.0]
    static = Observation.from_source(_capture(cfa, 0, 0), 45, 10, alpha=alpha, eta=2.0, radius=3, previous=True)
    assert static.own is not None and static.pooling is not None and static.pooling.active
    assert not changed_blocks(static, p.reuse_alpha).any()
    src = _capture(cfa, 0, 0, change=(4, slice(0, H), slice(0, W // 2), 1.25))
    obs = Observation.from_source(src, 45, 10, alpha=alpha, eta=2.0, radius=3, previous=True)
    changed = changed_blocks(obs, p.reuse_alpha)
    assert changed[:, :2].mean() >= 0.375 and changed[:, 2:].mean() < 0.3, changed.astype(int).tolist()
    # the rule itself: the pooled observation's test is its own window's (the pooled one gives other blocks here)
    import dataclasses

    own = dataclasses.replace(obs.own, previous=obs.previous)
    assert np.array_equal(changed, changed_blocks(own, p.reuse_alpha))
    pooled_alone = dataclasses.replace(obs, own=None)
    assert not np.array_equal(changed, changed_blocks(pooled_alone, p.reuse_alpha))


# ------------------------------------------------------------------ static scenes at low light (issue 25, items 1–2)
def _sim_static(cfa: str | None, rate: float, ticks: int = 400, size: int = 96):
    """The project's integrate-and-fire simulator (dispersion, dark pixels firing less regularly than bright ones) on
    a static camera crop: a dark scene (``rate`` = mean spikes per tick) and a bright one."""
    import skimage.data

    from spikeview.sim import SimConfig, StaticScene, simulate

    img = skimage.data.camera()[100:100 + size, 180:180 + size].astype(np.float32) / 255.0
    if cfa is not None:
        img = np.repeat(img[..., None], 3, axis=-1)
    return simulate(StaticScene(img), SimConfig(n_ticks=ticks, cfa=cfa or "none", rate=rate, seed=5))


@CFAS
@pytest.mark.parametrize("rate", [0.03, 0.1, 0.3], ids=["dark", "mid", "bright"])
def test_a_static_scene_pools_every_neighbour_at_every_light(cfa, rate):
    """≥ 95 % of a static scene's photosites take all ±3 windows at rest (a single κ for the frame once failed the
    dark tiles of a bright scene, and the velocity search picked noise in the dark: 75 % and 50 %)."""
    cap = _sim_static(cfa, rate)
    _, pool = temporal.pool_counts(cap, 195, 205, 3, cap.cfa)
    nb = pool.dtau / WINDOW - 1
    assert (nb >= 6).mean() >= 0.95, (nb >= 6).mean()
    assert pool.kind == "static", pool.reason
    moved = [np.abs(pool.shifts[k][pool.accepted[k]]).max(axis=-1) > 0 for k in pool.offsets]
    assert np.mean([m.mean() for m in moved]) <= 0.05


@CFAS
def test_low_light_static_tiles_grow_their_support_at_rest_to_the_bound(cfa, monkeypatch):
    """In the dark (0.3 spikes per photosite per window) a static tile goes on pooling beyond ±3 windows up to
    LOW_LIGHT_RADIUS; in bright light it stops at ±3 (its count already reaches LOW_LIGHT_COUNT)."""
    dark = _sim_static(cfa, 0.03)
    _, pool = temporal.pool_counts(dark, 195, 205, 3, dark.cfa)
    assert pool.extended and max(abs(k) for k in pool.extended) == temporal.LOW_LIGHT_RADIUS
    assert float(np.median(pool.dtau)) > 20 * WINDOW and "low light" in pool.reason
    monkeypatch.setattr(temporal, "LOW_LIGHT_RADIUS", 5)
    _, pool5 = temporal.pool_counts(dark, 195, 205, 3, dark.cfa)
    assert pool5.dtau.max() <= 11 * WINDOW and max(abs(k) for k in pool5.extended) == 5
    assert (pool.dtau > 7 * WINDOW).mean() > 0.9
    bright = _sim_static(cfa, 0.6)  # only its darkest tiles (under LOW_LIGHT_COUNT spikes over ±3 windows) go on
    _, pool_b = temporal.pool_counts(bright, 195, 205, 3, bright.cfa)
    assert (pool_b.dtau > 7 * WINDOW).mean() < 0.5


@CFAS
def test_a_moving_scene_in_the_dark_is_not_pooled_at_rest_beyond_radius(cfa):
    """The extension pools only at rest: content moving 4 photosites a window is never pooled from beyond ±3."""
    src = _capture(cfa, 0, 4, windows=12)
    _, pool = temporal.pool_counts(src, 60, 70, 3, src.cfa)
    nb = pool.dtau / WINDOW - 1
    assert nb[8:-8, 8:-8].max() <= 6


@CFAS
def test_the_fallback_denoises_each_photosite_at_its_own_noise(cfa):
    """The plan's one-pass fallback takes the prior's σ per pixel: the half that pooled nothing (16× the variance)
    is denoised harder than at the frame's RMS σ, the pooled half less hard (the RMS, set by the noisy half,
    over-smooths it: in a real scene that is its detail)."""
    from scipy.ndimage import gaussian_filter

    from spikeview.guided.baseline import baseline
    from spikeview.guided.priors.ffdnet import FFDNetDenoiser
    from spikeview.guided.observation import Observation

    rng = np.random.default_rng(3)
    h, w = 64, 128
    left = np.arange(w)[None, :] < w // 2
    dtau = np.where(left, 160.0, 10.0).astype(np.float32) * np.ones((h, 1), np.float32)
    y = (rng.binomial(dtau.astype(int), 0.3) / dtau).astype(np.float32)
    obs = Observation(y, cfa, 10, None if cfa is None else np.ones(3), 1.0, (0, 10), 5, None, dtau)
    prior = FFDNetDenoiser(color=cfa is not None)
    flat = baseline(obs, prior, use_mosaic=cfa is not None, use_cast=False)
    mapped = baseline(obs, prior, use_mosaic=cfa is not None, use_cast=False, sigma_map=True)

    def rough(x, sel):
        g = x if x.ndim == 2 else x.mean(axis=-1)
        return float(np.std((g - gaussian_filter(g, 2.0))[4:-4][:, sel]))

    assert rough(mapped, ~left[0]) < 0.9 * rough(flat, ~left[0])
    assert rough(mapped, left[0]) > 1.5 * rough(flat, left[0])


@CFAS
def test_a_dim_pan_is_seen_by_the_whole_frame_and_not_pooled_at_rest(cfa, monkeypatch):
    """At 0.1–0.4 spikes per photosite a window no tile shows a pan of 2 photosites a window above its noise; the
    whole frame does (its best velocity against the opposite one): its dim tiles are not held at rest and the support
    does not grow. A static scene at the same light is not taken for a pan (at rest, any shift matches it ~10 % better
    than none: the test never compares with zero)."""
    rng = np.random.default_rng(7)
    tex = gaussian_filter(rng.random((260, 280)), 3.0)
    tex = 0.005 + 0.04 * (tex - tex.min()) / (tex.max() - tex.min())  # 0.05–0.45 spikes a 10-tick window

    def capture(dx):
        out = np.zeros((9 * WINDOW, 192, 192), np.uint8)
        for k in range(9):
            r = tex[20:212, 40 - k * dx:232 - k * dx]
            for t in range(WINDOW):
                out[k * WINDOW + t] = rng.random((192, 192)) < r
        return ArraySource(out, cfa=cfa)

    _, moving = _pool(capture(2))
    assert "the frame pans" in moving.reason and not moving.extended, moving.reason
    _, still = _pool(capture(0))
    assert "pans" not in still.reason, still.reason
