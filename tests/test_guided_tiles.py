"""Per-tile plan (issue 15, item 2): the tile map follows each tile's noise, tiles cover the frame,
and a step-synchronous tiled run leaves no seam: it matches the whole-frame run pixel for pixel on a
uniform scene, and skips what each tile does not need (Bayer and monochrome alike)."""

from __future__ import annotations

import numpy as np
import pytest

from spikeview.errors import ParameterError
from spikeview.guided import tiles
from spikeview.guided.config import GuidedConfig
from spikeview.guided.observation import Observation
from spikeview.guided.plan import make_plan
from spikeview.guided.priors.base import PriorUnavailableError
from spikeview.guided.priors.ffdnet import FFDNetDenoiser
from spikeview.guided.sampler import GuidedSampler
from spikeview.guided.tiles import tile_spans
from spikeview.io.source import ArraySource

GAINS = np.array([1.0, 1.0, 1.0])


def _obs(rates: np.ndarray, cfa: str | None, ticks: int = 40, seed: int = 0) -> Observation:
    rng = np.random.default_rng(seed)
    src = ArraySource(rng.random((ticks,) + rates.shape) < rates, cfa=cfa)
    return Observation.from_source(src, ticks // 2, 10, alpha=GAINS if cfa else None, eta=2.0, radius=0)


def _net(cfa: str | None) -> FFDNetDenoiser:
    try:
        return FFDNetDenoiser(color=cfa is not None)
    except PriorUnavailableError as e:  # a real denoiser: random weights would say nothing about seams
        pytest.skip(str(e))


class Counting:
    """A prior that counts the pixels it denoises (the work a tiled run leaves out)."""

    def __init__(self, net):
        self.net, self.pixels, self.calls, self.sigmas = net, 0, 0, []
        self.channels, self.sigma_max = net.channels, net.sigma_max

    def denoise(self, x, sigma):
        self.pixels += x.shape[-2] * x.shape[-1]
        self.calls += 1
        self.sigmas.append(sigma)
        return self.net.denoise(x, sigma)


@pytest.mark.parametrize("n,size", [(1000, 128), (160, 64), (97, 64), (64, 64)])
def test_tiles_partition_the_frame_on_even_edges(n, size):
    spans = tile_spans(n, size)
    assert spans[0][0] == 0 and spans[-1][1] == n and all(a % 2 == 0 for a, _ in spans)
    assert all(b - a <= size + 2 for a, b in spans)
    assert all(b0 == a1 for (_, b0), (a1, _) in zip(spans, spans[1:], strict=False))  # no gap, no overlap
    assert len(tile_spans(1000, 128)) == 8  # 1000×1000 in 64 tiles, as the plan line


@pytest.mark.parametrize("cfa", ["RGGB", None], ids=["bayer", "mono"])
def test_tile_map_follows_the_noise_of_each_tile(cfa):
    rates = np.full((96, 192), 0.3)
    rates[:, :64] = 1.0  # a saturated (noise-free) left third
    obs = _obs(rates, cfa)
    plan = make_plan(obs, GuidedConfig(tile=64))
    tm = plan.tile_map
    assert plan.diffusion and tm is not None and (tm.rows, tm.cols) == (2, 3)
    counts = tm.counts()
    assert sum(counts.values()) == len(tm.tiles) == tm.grid().size == 6
    for t in tm.tiles:
        if t.x1 <= 64:
            assert t.kind == "skipped" and t.fallback == "tfp" and t.steps == 0
        else:
            assert t.kind == "full" and t.steps == 6 and t.join == 0
    assert tm.grid().tolist() == [[0, 2, 2], [0, 2, 2]]
    line = plan.reasons["tiles"]
    assert line.startswith("192×96 in 6 tiles of 64 px: 2 skipped (noise below target), 0 short, 4 full")
    assert "67% of the whole frame's prior work" in line and "192×96 in" in str(plan)
    assert tm.as_dict()["counts"] == counts and len(tm.as_dict()["tiles"]) == 6
    off = make_plan(obs, GuidedConfig(tile=0))
    assert off.tile_map is None and "off" in off.reasons["tiles"]
    assert "DPS" in make_plan(obs, GuidedConfig(tile=64, guidance="dps")).reasons["tiles"]
    with pytest.raises(ParameterError, match="guided.tile"):
        GuidedConfig(tile=16)


@pytest.mark.parametrize("cfa", ["RGGB", None], ids=["bayer", "mono"])
def test_a_short_tile_joins_the_frames_ladder_late(cfa, monkeypatch):
    rates = np.full((64, 128), 0.3)
    rates[:, 64:] = 0.99  # bright: less noise, but still above the target
    obs = _obs(rates, cfa, ticks=80)
    p = GuidedConfig(tile=64, noise_target=1.0 / 255.0, precision="float32", steps=4)
    # short tiles that leave out too little of the work take the whole ladder (the margins would cost more)
    worth = make_plan(obs, p).tile_map
    assert worth.counts()["short"] == (1 if worth.work() <= tiles.PAY_WORK else 0)
    if worth.counts()["short"] == 0:
        assert worth.work_if_short > tiles.PAY_WORK and "all full" in worth.summary()
    monkeypatch.setattr(tiles, "PAY_WORK", 1.0)
    tm = make_plan(obs, p).tile_map
    dark, bright = tm.tiles
    assert dark.kind == "full" and dark.join == 0
    assert bright.kind == "short" and 0 < bright.join < p.steps and bright.steps == p.steps - bright.join
    assert bright.t_start < dark.t_start and tm.work() < 1.0
    # the run: while the bright tile waits, the prior sees the dark tile and its margin only, and the
    # bright tile shows its start estimate
    prior = Counting(_net(cfa))
    frames = []
    out = GuidedSampler(prior=prior).run(obs, p, callback=lambda s, n, im: frames.append(im))
    assert np.isfinite(out).all() and len(frames) == p.steps
    assert prior.pixels < p.steps * 64 * 128 and prior.calls == p.steps  # one rectangle once both take part
    # the prior is told every pixel's own level: the waiting bright pixels in the dark tile's margin sit lower
    first = np.asarray(prior.sigmas[0])
    assert first.ndim == 4 and first.shape[-1] > 64 and first[..., -1].max() < first[..., 0].min()
    from spikeview.guided.baseline import start_estimate

    plan = make_plan(obs, p)
    y0 = start_estimate(obs, plan.mosaic, plan.cast, p.demosaic)
    assert np.allclose(frames[0][:, 64:], y0[:, 64:]) and not np.allclose(frames[-1][:, 64:], y0[:, 64:])


@pytest.mark.parametrize("cfa", ["RGGB", None], ids=["bayer", "mono"])
def test_tiled_uniform_scene_matches_the_whole_frame_everywhere(cfa, monkeypatch):
    """The issue's seam test, strict: every pixel (borders included) within 1/255 of the whole-frame
    run, and the gradient across tile borders no larger than the whole frame's at the same columns."""
    obs = _obs(np.full((128, 128), 0.3), cfa, seed=1)
    smp = GuidedSampler(prior=_net(cfa))
    p = GuidedConfig(precision="float32", steps=3)
    whole = smp.run(obs, p)
    monkeypatch.setattr(tiles, "MAX_AREA", 2000)  # cut the frame into 2×2 rectangles of one tile each
    monkeypatch.setattr(tiles.TileMap, "pays", lambda self: True)  # all tiles full: tiled on purpose
    seen = []
    orig = tiles._rectangles
    monkeypatch.setattr(tiles, "_rectangles", lambda *a: seen.append(orig(*a)) or seen[-1])
    tiled = smp.run(obs, p.replace(tile=64))
    assert smp.info.mode == "tiled" and tiled.shape == whole.shape and np.isfinite(tiled).all()
    assert all(len(r) == 4 for r in seen)  # the test exercises the margins, not one whole-frame rectangle
    d = np.abs(tiled - whole)
    assert d.max() < 1.0 / 255, f"largest difference {255 * d.max():.3f}/255"
    gray = (lambda a: a.mean(axis=-1) if a.ndim == 3 else a)
    edge = tile_spans(128, 64)[1][0]
    gt, gw = np.abs(np.diff(gray(tiled), axis=1)), np.abs(np.diff(gray(whole), axis=1))
    assert gt[:, edge - 1].mean() <= gw[:, edge - 1].mean() + 0.1 / 255
    assert gt[:, edge - 1].mean() <= 1.2 * np.delete(gt, edge - 1, axis=1).mean()


@pytest.mark.parametrize("cfa", ["RGGB", None], ids=["bayer", "mono"])
def test_tiled_run_skips_what_a_tile_does_not_need(cfa):
    rates = np.full((64, 384), 0.3)
    rates[:, :192] = 1.0  # saturated: the left half needs no diffusion
    obs = _obs(rates, cfa, seed=2)
    net = _net(cfa)
    p = GuidedConfig(precision="float32", steps=2, tile=64)
    whole_prior, tiled_prior = Counting(net), Counting(net)
    whole = GuidedSampler(prior=whole_prior).run(obs, p.replace(tile=0))
    frames = []
    smp = GuidedSampler(prior=tiled_prior)
    tiled = smp.run(obs, p, callback=lambda s, n, im: frames.append((s, n, im)))
    assert smp.info.mode == "tiled" and tiled.shape == whole.shape and np.isfinite(tiled).all()
    # the prior saw the diffused tiles and their context, not the skipped third
    assert tiled_prior.pixels < 0.75 * whole_prior.pixels
    # every step reports the whole frame; the skipped third is its fallback from the first step on
    assert [s for s, _, _ in frames] == [1, 2] and all(im.shape == whole.shape for *_, im in frames)
    from spikeview.guided.baseline import start_estimate

    plan = make_plan(obs, p)
    tfp = start_estimate(obs, plan.mosaic, plan.cast, p.demosaic)
    far = slice(0, 192 - tiles.BLEND)
    assert np.allclose(tiled[:, far], tfp[:, far]) and np.allclose(frames[0][2][:, far], tfp[:, far])
    # the diffused estimate fades in over BLEND pixels of the skipped side (more of it nearer the diffused tiles)
    d = np.abs(tiled - tfp).reshape(64, 384, -1).mean(axis=(0, 2))
    zone = d[192 - tiles.BLEND:192]
    assert zone[-4:].mean() > 1.0 / 255 and zone[-4:].mean() > 2 * zone[:4].mean()
    # no seam where the skipped tiles meet the diffused ones: the cross-fade is no steeper than the image
    g = tiled.mean(axis=-1) if tiled.ndim == 3 else tiled
    gx = np.abs(np.diff(g, axis=1))
    assert gx[:, 192 - tiles.BLEND:192].mean() <= gx[:, 200:].mean() + 2.0 / 255


@pytest.mark.parametrize("cfa", ["RGGB", None], ids=["bayer", "mono"])
def test_output_metadata_records_the_tile_map(cfa, tmp_path):
    from spikeview.export import read_export_metadata
    from spikeview.pipeline import write_sequence
    from spikeview.recipe import Recipe

    rates = np.full((64, 192), 0.3)
    rates[:, :64] = 1.0
    src = ArraySource(np.random.default_rng(0).random((40,) + rates.shape) < rates, cfa=cfa)
    recipe = Recipe().with_values({"run.method": "guided", "guided.tile": 64, "guided.steps": 1,
                                   "guided.precision": "float32", "guided.temporal_radius": 0})
    write_sequence(src, recipe, [20], tmp_path / "f.npy")
    plan = read_export_metadata(tmp_path / "f.npy")["plan"]
    assert plan["tiles"].startswith("192×64 in 3 tiles of 64 px: 1 skipped (noise below target), 0 short, 2 full")
    assert plan["precision"]
    write_sequence(src, recipe.with_values({"guided.tile": 0}), [20], tmp_path / "g.npy")
    assert read_export_metadata(tmp_path / "g.npy")["plan"]["tiles"].startswith("off (guided.tile = 0)")
