"""The guided benchmark's scoring and scene set (spikeview.bench): gain-fitted metrics, clipping, scene recipes."""

from __future__ import annotations

import numpy as np
import pytest

from spikeview.bench.data import GROUPS, SCENES, TUNE_SCENES, scene_image, spikezoo_clips
from spikeview.bench.guided import clipped_fraction, fit_gain, pareto, score


def _gt(seed=0):
    rng = np.random.default_rng(seed)
    return rng.uniform(0.05, 0.9, (24, 24, 3)).astype(np.float32)


def test_score_is_blind_to_a_per_channel_gain_but_not_to_clipping():
    gt = _gt()
    g = np.array([0.5, 1.3, 0.8], dtype=np.float32)
    np.testing.assert_allclose(fit_gain(gt * g, gt), 1.0 / g, rtol=1e-6)
    assert score(gt * g, gt)[0] > 100.0  # exact up to the gain: (near) infinite PSNR
    clipped = np.clip(gt * 2.0, 0.0, 1.0)  # over-exposed: the top of the range is lost
    assert score(clipped, gt)[0] < 30.0
    assert clipped_fraction(clipped) > 0.3 and clipped_fraction(gt) == 0.0


def test_score_of_a_gray_frame_uses_one_gain():
    gt = _gt()[..., 0]
    assert score(gt * 0.4, gt)[0] > 100.0


def test_pareto_front():
    # (seconds, psnr): the second is dominated by the first (slower and worse)
    assert pareto([(1.0, 30.0), (2.0, 29.0), (0.1, 20.0), (3.0, 31.0)]) == [0, 2, 3]


def test_every_group_has_tuning_and_held_out_scenes():
    for g in GROUPS:
        names = [n for n, s in SCENES.items() if s[0] == g]
        assert any(n in TUNE_SCENES for n in names) and any(n not in TUNE_SCENES for n in names), g


@pytest.mark.parametrize("recipe,lo,hi", [("highkey:chelsea", 0.4, 1.0), ("lowkey:coffee", 0.0, 0.05),
                                          ("lamps:astronaut", 0.0, 0.3)])
def test_scene_recipes_set_the_key(recipe, lo, hi):
    img = scene_image(recipe)
    assert img.dtype == np.float32 and img.min() >= 0.0 and img.max() <= 1.0
    assert lo <= float(np.median(img)) <= hi
    if recipe.startswith("lamps"):
        assert (img.max(axis=-1) >= 0.999).mean() >= 0.015  # ~2 % of the pixels are lamps at full scale


def test_spikezoo_clips_found_in_an_unzipped_wheel(tmp_path):
    from PIL import Image

    base = tmp_path / "spikezoo" / "data" / "base" / "test"
    (base / "spike").mkdir(parents=True)
    (base / "gt").mkdir()
    (base / "spike" / "a.dat").write_bytes(b"\0" * 12500)
    Image.fromarray(np.full((250, 400), 128, dtype=np.uint8)).save(base / "gt" / "a.png")
    (base / "spike" / "no_gt.dat").write_bytes(b"\0" * 12500)
    clips = spikezoo_clips(tmp_path)
    assert [c.name for c in clips] == ["test/a"]
    assert clips[0].gt.shape == (250, 400) and clips[0].gt.max() == pytest.approx(128 / 255)
    assert spikezoo_clips(tmp_path / "nothing") == []


@pytest.mark.parametrize("cfa", ["RGGB", "none"])
def test_the_benchmarks_default_row_is_what_the_cli_writes(tmp_path, cfa):
    """`spikeview bench`'s "guided (default)" row is `spikeview reconstruct --method guided --at T --out x.npy`,
    bit for bit (the row once built its observation without the pooled neighbours the product uses)."""
    import numpy as np

    from spikeview.bench.guided import DEFAULT_ROW, Sequence, _methods
    from spikeview.cli.main import main
    from spikeview.guided.config import GuidedConfig
    from spikeview.guided.sampler import load_prior
    from spikeview.io import open_source

    cap = tmp_path / "c.dat"
    assert main(["simulate", "--demo", "--size", "48", "--ticks", "90", "--cfa", cfa, "--out", str(cap)]) == 0
    assert main(["reconstruct", str(cap), "--method", "guided", "--at", "45", "--out", str(tmp_path / "x.npy")]) == 0
    cli = np.load(tmp_path / "x.npy")[0]  # (frames, H, W[, 3])
    with open_source(str(cap)) as src:
        prior = load_prior(GuidedConfig(), 3 if cfa != "none" else 1)
        fn = dict((name, f) for name, _, f in _methods(prior, quick=False))[DEFAULT_ROW]
        row = fn(Sequence(src), 45)
    assert row.shape == cli.shape and row.dtype == cli.dtype
    assert np.array_equal(row, cli)


def test_colour_scores_show_what_a_per_channel_gain_hides():
    import numpy as np

    from spikeview.metrics import colour_scores

    rng = np.random.default_rng(0)
    truth = rng.random((32, 32, 3)).astype(np.float32) * 0.8
    same = colour_scores(truth * 0.5, truth)  # an exposure: one gain undoes it
    assert same["psnr_1gain"] > 60 and same["delta_e00"] < 1e-3 and same["wb_angle"] < 1e-3
    cast = colour_scores(truth * np.array([0.6, 1.0, 0.5], np.float32), truth)  # a sensor's colour cast
    p, _ = score(np.clip(truth * np.array([0.6, 1.0, 0.5], np.float32), 0, 1), truth)
    assert cast["wb_angle"] > 5 and cast["delta_e00"] > 3 and cast["psnr_1gain"] < p - 5
    mono = colour_scores(truth[..., 0] * 0.7, truth[..., 0])
    assert mono["psnr_1gain"] > 60 and mono["delta_e00"] == 0.0 and mono["wb_angle"] == 0.0
