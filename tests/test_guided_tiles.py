"""Per-tile plan (issue 15, item 2): the tile map follows each tile's noise, tiles cover the frame,
and a tiled run leaves no seam a person could see (Bayer and monochrome alike)."""

from __future__ import annotations

import numpy as np
import pytest

from spikeview.errors import ParameterError
from spikeview.guided.config import GuidedConfig
from spikeview.guided.observation import Observation
from spikeview.guided.plan import make_plan
from spikeview.guided.priors.base import PriorUnavailableError
from spikeview.guided.priors.ffdnet import FFDNetDenoiser
from spikeview.guided.sampler import GuidedSampler
from spikeview.guided.tiles import OVERLAP, tile_spans
from spikeview.io.source import ArraySource

GAINS = np.array([1.0, 1.0, 1.0])


def _obs(rates: np.ndarray, cfa: str | None, ticks: int = 40, seed: int = 0) -> Observation:
    rng = np.random.default_rng(seed)
    src = ArraySource(rng.random((ticks,) + rates.shape) < rates, cfa=cfa)
    return Observation.from_source(src, ticks // 2, 10, alpha=GAINS if cfa else None, eta=2.0)


@pytest.mark.parametrize("n,size", [(1000, 256), (160, 96), (97, 64), (64, 64)])
def test_tiles_cover_the_frame_with_overlap(n, size):
    spans = tile_spans(n, size)
    assert spans[0][0] == 0 and spans[-1][1] == n and all(a % 2 == 0 for a, _ in spans)
    assert all(b - a <= size + 2 for a, b in spans)
    for (_, b0), (a1, _) in zip(spans, spans[1:], strict=False):
        assert b0 - a1 >= OVERLAP - 2  # neighbours share at least the overlap
    covered = np.zeros(n, bool)
    for a, b in spans:
        covered[a:b] = True
    assert covered.all()


@pytest.mark.parametrize("cfa", ["RGGB", None], ids=["bayer", "mono"])
def test_tile_map_follows_the_noise_of_each_tile(cfa):
    rates = np.full((96, 192), 0.3)
    rates[:, :96] = 1.0  # a saturated (noise-free) left half
    obs = _obs(rates, cfa)
    plan = make_plan(obs, GuidedConfig(tile=64))
    tm = plan.tile_map
    assert plan.diffusion and tm is not None
    counts = tm.counts()
    assert counts["skipped"] >= 2 and counts["full"] >= 2 and sum(counts.values()) == len(tm.tiles) == tm.grid().size
    for t in tm.tiles:
        if t.x1 <= 96:
            assert t.kind == "skipped" and t.fallback == "tfp"
        if t.x0 >= 96:
            assert t.kind == "full" and t.steps == 6
    assert "96×192 in" in str(plan) and "skipped (noise below target)" in plan.reasons["tiles"]
    assert make_plan(obs, GuidedConfig()).tile_map is None and "off" in make_plan(obs, GuidedConfig()).reasons["tiles"]
    with pytest.raises(ParameterError, match="guided.tile"):
        GuidedConfig(tile=16)


@pytest.mark.parametrize("cfa", ["RGGB", None], ids=["bayer", "mono"])
def test_tiled_uniform_scene_has_no_seam(cfa):
    obs = _obs(np.full((160, 160), 0.3), cfa, seed=1)
    try:
        net = FFDNetDenoiser(color=cfa is not None)
    except PriorUnavailableError as e:  # a real denoiser: random weights amplify the tile edges instead of removing noise
        pytest.skip(str(e))
    smp = GuidedSampler(prior=net)
    p = GuidedConfig(precision="float32")
    whole = smp.run(obs, p)
    tiled = smp.run(obs, p.replace(tile=96))
    assert smp.info.mode == "tiled" and tiled.shape == whole.shape and np.isfinite(tiled).all()
    gray = tiled.mean(axis=-1) if tiled.ndim == 3 else tiled
    inner = [b for (_, b) in tile_spans(160, 96)[:-1]] + [a for (a, _) in tile_spans(160, 96)[1:]]
    gx = np.abs(np.diff(gray, axis=1))[8:-8]
    at_borders = gx[:, [c - 1 for c in inner]].mean()
    inside = np.delete(gx, [c - 1 for c in inner], axis=1).mean()
    # measured (BENCHMARKS.md): border/inside 0.85 (Bayer), 1.08 (mono); tiled − whole mean 0.3–0.6/255,
    # but up to 1.8–3.7/255 at single pixels: the "within 1/255" holds on average, not everywhere
    assert at_borders <= 1.15 * inside  # the seams are no sharper than the texture of the remaining noise
    d = np.abs(tiled - whole)[16:-16, 16:-16]
    assert d.mean() < 1.0 / 255
