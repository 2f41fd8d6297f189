"""One test per rule that a planted one-line bug once slipped past (issue 18; ``tests/README.md`` lists them).

Each rule is pinned at its threshold or on its exact value, so moving the threshold, swapping a
branch or dropping a division fails here. Monochrome and Bayer both, where the rule applies to both.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from spikeview.guided.config import GuidedConfig
from spikeview.guided.observation import Observation
from spikeview.guided.plan import make_plan
from spikeview.pipeline import SequenceState, exposure_mapping, output_white
from spikeview.recipe import Recipe
from test_guided_helpers import make_source

CFAS = ["RGGB", None]


def _obs(cfa, window=10, kind="ramp", ticks=60):
    src = make_source(kind, 16, 16, ticks=ticks, cfa=cfa)
    alpha = np.array([2.0, 2.0, 2.0]) if cfa else None
    return Observation.from_source(src, src.n_frames // 2, window, alpha=alpha, eta=2.0, radius=0)


# ------------------------------------------------------------------- the plan's diffusion rules
@pytest.mark.parametrize("cfa", CFAS)
def test_plan_skips_diffusion_exactly_at_or_below_the_noise_target(cfa):
    obs = _obs(cfa)
    smax = float(make_plan(obs, GuidedConfig()).judged_sigma)  # the σ the rule compares (its worst block, its white)
    assert smax > 0
    above = make_plan(obs, GuidedConfig(noise_target=smax * 0.98))  # σ 2 % above the target: diffusion
    assert above.diffusion, above.reasons["diffusion"]
    at = make_plan(obs, GuidedConfig(noise_target=smax * 1.02))  # σ just meets the target: skipped
    assert not at.diffusion, at.reasons["diffusion"]


@pytest.mark.parametrize("cfa", CFAS)
def test_plan_falls_back_to_tfp_exactly_at_a_quarter_of_the_target(cfa):
    obs = _obs(cfa)
    smax = float(make_plan(obs, GuidedConfig()).judged_sigma)
    # σ a little above target/4: the baseline; a little below: the TFP frame itself
    assert make_plan(obs, GuidedConfig(noise_target=4 * smax * 0.98)).fallback == "baseline"
    assert make_plan(obs, GuidedConfig(noise_target=4 * smax * 1.02)).fallback == "tfp"


# ------------------------------------------------------------------------------ knob_status
#: the sampler's knobs (inert when the plan skips diffusion); guided.temporal_radius, which also acts
#: on the fallback's input, is tested with the temporal pooling
SAMPLER_KNOBS = ("guided.s", "guided.k", "guided.levels", "guided.t_start", "guided.lam")


@pytest.mark.parametrize("cfa", CFAS)
@pytest.mark.parametrize("guidance", ["hqs", "dps"])
def test_knob_status_for_every_knob_under_both_guidance_rules(cfa, guidance):
    from spikeview.guided.knobs import KNOBS, knob_status

    cfg = GuidedConfig(guidance=guidance, levels=2, t_start=0.2, data_steps=1)
    live = dataclasses.replace(make_plan(_obs(cfa), cfg), diffusion=True, quantise=True, levels=2,
                               sigma=np.full(3 if cfa else 1, 0.01))
    status = knob_status(cfg, live)
    assert set(SAMPLER_KNOBS) <= set(KNOBS) == set(status)
    expect_lam = None if guidance == "hqs" else "DPS"
    for knob, why in ((k, status[k]) for k in SAMPLER_KNOBS):
        if knob == "guided.lam" and expect_lam:
            assert why and expect_lam in why, (knob, why)
        else:
            assert why is None, (knob, why)
    # each knob's own "inert" condition, one at a time
    s = knob_status(dataclasses.replace(cfg, data_steps=0), live)["guided.s"]
    assert (s is not None) == (guidance == "hqs"), s  # DPS: s is the step size, data steps or not
    assert knob_status(cfg, dataclasses.replace(live, quantise=False))["guided.k"] is not None
    assert knob_status(cfg, dataclasses.replace(live, levels=0))["guided.levels"] is not None
    assert knob_status(cfg, dataclasses.replace(live, sigma=np.full(3 if cfa else 1, 0.25)))["guided.t_start"] is not None
    lam = knob_status(cfg, live)["guided.lam"]
    assert (lam is None) == (guidance == "hqs"), lam
    # no diffusion: nothing acts
    off = knob_status(cfg, dataclasses.replace(live, diffusion=False))
    assert all(off[k] and "skips diffusion" in off[k] for k in SAMPLER_KNOBS), off


# ------------------------------------------------------------------------- the exposure mapping
@pytest.mark.parametrize("shape", [(4, 4, 3), (4, 4)], ids=["bayer", "mono"])
def test_exposure_mapping_divides_the_black_level_by_the_white_point(shape):
    recipe = Recipe().with_values({"export.black": 0.2, "export.white": 2.5})
    for out in ("x.png", "x.mp4", "x.exr", "x.npy"):
        cfg, expose = exposure_mapping(recipe, SequenceState(None, 1.0), out)
        assert cfg.black == pytest.approx(0.2 / 2.5) and cfg.white == 1.0, out
        frame = np.full(shape, 1.25, dtype=np.float32)
        np.testing.assert_allclose(expose(frame), 0.5)


def test_output_white_uses_the_sequence_estimate_then_the_recipe():
    assert output_white(Recipe(), SequenceState(None, 2.75)) == pytest.approx(2.75)
    assert output_white(Recipe(), SequenceState(np.ones(3), 0.4)) == pytest.approx(0.4)
    assert output_white(Recipe().with_values({"export.white": 3.0}), SequenceState(None, 2.75)) == 3.0
    assert output_white(Recipe(), SequenceState(None, None)) == 1.0


@pytest.mark.parametrize("shape", [(4, 4, 3), (4, 4)], ids=["bayer", "mono"])
def test_npy_mapping_is_clipped_to_0_1_and_exr_is_not(shape):
    frame = np.linspace(-1.0, 6.0, int(np.prod(shape)), dtype=np.float32).reshape(shape)
    state = SequenceState(None, 2.0)
    npy = exposure_mapping(Recipe(), state, "x.npy")[1](frame)
    assert npy.min() == 0.0 and npy.max() == 1.0
    exr = exposure_mapping(Recipe(), state, "x.exr")[1](frame)
    assert exr.max() == pytest.approx(3.0) and exr.min() == pytest.approx(-0.5)


@pytest.mark.parametrize("cfa", ["RGGB", "none"])
def test_npy_output_of_a_run_is_bounded(tmp_path, cfa):
    """End to end: a white point far below the data still gives a .npy in [0, 1] (full scale reached)."""
    from spikeview.cli.main import main
    from spikeview.io.plain import write_plain

    rng = np.random.default_rng(1)
    write_plain(tmp_path / "c.dat", (rng.random((40, 16, 16)) < 0.6).astype(np.uint8))
    assert main(["reconstruct", str(tmp_path / "c.dat"), "--width", "16", "--height", "16", "--cfa", cfa,
                 "--at", "20", "--white", "0.05", "--out", str(tmp_path / "f.npy")]) == 0
    f = np.load(tmp_path / "f.npy")
    assert f.min() >= 0.0 and f.max() == 1.0


# --------------------------------------------------------------------------- open lower bounds
@pytest.mark.parametrize("flag, path, bound", [("--white", "export.white", ">= 1e-06"), ("--eta", "classical.eta", "> 0"),
                                               ("--lam", "guided.lam", "> 0")])
def test_open_lower_bounds_reject_the_bound_itself(tmp_path, capsys, flag, path, bound):
    from spikeview.cli.main import main
    from spikeview.errors import ParameterError
    from spikeview.io.plain import write_plain

    with pytest.raises(ParameterError):
        Recipe().with_values({path: 0.0})
    Recipe().with_values({path: 1e-3})  # just above the bound is fine
    from spikeview.classical.config import ClassicalConfig
    from spikeview.export import ExportConfig

    typed = {"export.white": lambda v: ExportConfig(white=v), "classical.eta": lambda v: ClassicalConfig(eta=v),
             "guided.lam": lambda v: GuidedConfig(lam=v)}[path]
    with pytest.raises(ParameterError):
        typed(0.0)  # the library's typed configs too
    typed(1e-3)
    write_plain(tmp_path / "c.dat", np.zeros((20, 8, 8), dtype=np.uint8))
    rc = main(["reconstruct", str(tmp_path / "c.dat"), "--width", "8", "--height", "8", flag, "0",
               "--out", str(tmp_path / "f.npy")])
    err = capsys.readouterr().err
    assert rc == 1 and flag in err and bound in err and "this is a bug" not in err, err
    assert not (tmp_path / "f.npy").exists()


# ------------------------------------------------------------------- the classical demosaic rule
def test_classical_auto_demosaic_reads_the_noisiest_plane():
    """Three clean Bayer planes and one noisy one: the noise of the noisiest decides (bilinear)."""
    from spikeview.classical.reconstruct import auto_demosaic

    yy, xx = np.mgrid[0:32, 0:32]
    mosaic = 0.4 + 0.1 * np.sin(xx / 6.0) * np.cos(yy / 5.0)
    assert auto_demosaic(mosaic, "RGGB")[0] == "malvar2004"
    for i, j in ((0, 0), (1, 1), (0, 1)):
        noisy = mosaic.copy()
        noisy[i::2, j::2] += np.random.default_rng(3).normal(0, 0.2, noisy[i::2, j::2].shape)
        name, why = auto_demosaic(noisy, "RGGB")
        assert name == "bilinear" and "noise dominates" in why, (i, j, why)


# ----------------------------------------------------------------- keyframes and chunk invariance
GUIDED_FAST = {"run.method": "guided", "guided.steps": 2, "guided.seed": 3, "guided.warm_start": True,
               "guided.self_ensemble": False, "guided.diffusion": "always"}


def _guided(src, centres, recipe, state):
    from spikeview.pipeline import reconstruct_windows

    return np.stack([np.asarray(f) for f in reconstruct_windows(src, centres, recipe, state)])


@pytest.mark.parametrize("cfa", CFAS)
def test_guided_chains_restart_at_every_keyframe(monkeypatch, cfa):
    """Warm-start chains restart at every KEYFRAME-th window: a run that starts on a keyframe gives the
    frames of the longer run, and one that starts between keyframes does not (the chain matters)."""
    import spikeview.pipeline as pipeline

    monkeypatch.setattr(pipeline, "KEYFRAME", 3)
    src = make_source("texture", 16, 16, ticks=120, cfa=cfa)
    recipe = Recipe().with_values({**GUIDED_FAST, "classical.window": 10})
    state = pipeline.prepare_sequence(src, recipe)
    centres = [10 + 10 * i for i in range(6)]
    whole = _guided(src, centres, recipe, state)
    np.testing.assert_array_equal(_guided(src, centres[3:], recipe, state), whole[3:])
    assert not np.array_equal(_guided(src, centres[4:5], recipe, state)[0], whole[4])


@pytest.mark.parametrize("cfa", ["RGGB", "none"])
def test_chunks_across_a_keyframe_give_the_frames_of_one_chunk(tmp_path, monkeypatch, cfa):
    """The batch path with keyframe 3: chunks of 2 (starting between keyframes) = one chunk of 6."""
    pytest.importorskip("zarr")
    import spikeview.pipeline as pipeline
    from spikeview.cluster.reconstruct import reconstruct_to_store
    from spikeview.cluster.store import check_store
    from spikeview.io.plain import write_plain

    # imported before the patch: BatchJob's default keyframe is bound when spikeview.cluster.run is first
    # imported, and a first import under the patch left it at 3 for every later test of the process
    import spikeview.cluster.run  # noqa: F401

    monkeypatch.setattr(pipeline, "KEYFRAME", 3)
    monkeypatch.setattr("spikeview.cluster._compute.DEFAULT_KEYFRAME", 3, raising=False)
    monkeypatch.setattr("spikeview.cluster.reconstruct.DEFAULT_KEYFRAME", 3, raising=False)
    import spikeview.cluster._compute as compute

    rng = np.random.default_rng(4)
    write_plain(tmp_path / "c.dat", (rng.random((80, 16, 16)) < np.linspace(0.1, 0.8, 16)).astype(np.uint8),
                cfa=None if cfa == "none" else cfa)
    recipe = Recipe().with_values({**GUIDED_FAST, "classical.window": 10, "run.range": "10:70:10",
                                   "stream.width": 16, "stream.height": 16, "stream.cfa": cfa})
    stores = {}
    for chunk in (6, 2):
        out = tmp_path / f"c{chunk}.zarr"
        reconstruct_to_store(tmp_path / "c.dat", recipe, out, chunk=chunk)
        check = check_store(out)
        assert check.attrs["keyframe"] == 3 == compute.DEFAULT_KEYFRAME
        stores[chunk] = np.concatenate([check.read_chunk(i) for i in range(check.n_chunks)])
    np.testing.assert_array_equal(stores[2], stores[6])


# ------------------------------------------------------------------------- resume skips done chunks
@pytest.mark.parametrize("cfa", ["RGGB", "none"])
def test_resume_computes_only_the_windows_of_unfinished_chunks(tmp_path, monkeypatch, cfa):
    pytest.importorskip("zarr")
    import spikeview.pipeline as pipeline
    from spikeview.cluster.reconstruct import reconstruct_to_store
    from spikeview.errors import Cancelled
    from spikeview.io.plain import write_plain

    rng = np.random.default_rng(5)
    write_plain(tmp_path / "c.dat", (rng.random((60, 16, 16)) < 0.4).astype(np.uint8))
    recipe = Recipe().with_values({"classical.window": 4, "run.range": "2:42:4", "stream.width": 16,
                                   "stream.height": 16, "stream.cfa": cfa})  # 10 windows
    computed = []
    real = pipeline.reconstruct_windows

    def counting(source, centres, *a, **k):
        for f in real(source, centres, *a, **k):
            computed.append(1)
            yield f

    monkeypatch.setattr(pipeline, "reconstruct_windows", counting)
    out = tmp_path / "s.zarr"
    chunks = []
    with pytest.raises(Cancelled):
        reconstruct_to_store(tmp_path / "c.dat", recipe, out, chunk=4, cancel=lambda: chunks.append(1) or len(chunks) >= 2)
    assert len(computed) == 8  # chunks 0 and 1
    computed.clear()
    report = reconstruct_to_store(tmp_path / "c.dat", recipe, out, resume=True)
    assert len(computed) == 2 and report.windows == 2 and report.chunks_skipped == 2  # chunk 2 only
