"""The guided path's device (issue 28), held honest on a machine without a GPU.

``guided.device`` governs the prior, the data term, the tiles, the start estimate and the temporal
pooling's alignment; these tests run every device-aware stage on the CPU through the same code and
check it gives today's pixels, that a device that is not there is refused in one sentence, that the
torch alignment a GPU runs makes exactly the numpy path's decisions, and that tensors on the wrong
device raise instead of being silently copied. The GPU figures come from ``benchmarks/gpu_check.sh``.
"""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
import torch

from spikeview.errors import ParameterError
from spikeview.guided.config import GuidedConfig
from spikeview.guided.device import check_device_name, cuda_count, resolve_device

NO_GPU = cuda_count() == 0


@pytest.fixture(scope="module", params=["RGGB", None], ids=["bayer", "mono"])
def capture(request):
    from spikeview.sim import SimConfig, demo_scene, simulate

    return simulate(demo_scene(size=96, seed=0), SimConfig(n_ticks=90, width=96, height=96, cfa=request.param or "none", seed=3))


def test_device_names_are_checked_in_one_sentence():
    assert check_device_name("CUDA:1") == "cuda:1" and check_device_name("auto") == "auto"
    for bad in ("gpu", "cuda:", "cuda:x", "mps", ""):
        with pytest.raises(ParameterError, match="use auto, cpu, cuda or cuda:N"):
            GuidedConfig(device=bad)


@pytest.mark.skipif(not NO_GPU, reason="this machine has a CUDA GPU")
def test_cuda_where_there_is_none_is_refused_and_auto_is_the_cpu():
    assert resolve_device("auto") == torch.device("cpu") and resolve_device(None) == torch.device("cpu")
    for spec in ("cuda", "cuda:1"):
        with pytest.raises(ParameterError) as e:
            resolve_device(spec)
        msg = str(e.value)
        assert msg.count(". ") == 0 and f"--device {spec}" in msg and "sees none" in msg and "--device auto or cpu" in msg


@pytest.mark.skipif(not NO_GPU, reason="this machine has a CUDA GPU")
@pytest.mark.parametrize("cfa", ["RGGB", "none"])
def test_cli_device_cuda_without_a_gpu_says_so_in_one_sentence(tmp_path, cfa):
    from spikeview.cli.main import main

    path = tmp_path / "c.dat"
    assert main(["simulate", "--demo", "--size", "32", "--ticks", "40", "--cfa", cfa, "--out", str(path)]) == 0
    r = subprocess.run([sys.executable, "-m", "spikeview", "reconstruct", str(path), "--method", "guided", "--at", "20",
                        "--device", "cuda", "--out", str(tmp_path / "o.exr")], capture_output=True, text=True, timeout=300)
    assert r.returncode != 0 and "Traceback" not in r.stderr
    assert "--device cuda (guided.device) asks for a CUDA GPU" in r.stderr
    assert not (tmp_path / "o.exr").exists()


def _frames(capture, **values):
    from spikeview.pipeline import reconstruct_windows
    from spikeview.recipe import Recipe

    recipe = Recipe().with_values({"run.method": "guided", "guided.precision": "float32", "guided.steps": 3, **values})
    infos: list = []
    frames = list(reconstruct_windows(capture, [35, 45], recipe, infos=infos))
    return np.stack(frames), infos


@pytest.mark.parametrize("tile", [0, 64])
def test_device_cpu_through_the_device_aware_code_gives_the_default_pixels(capture, tile):
    a, infos = _frames(capture, **{"guided.tile": tile})
    b, infos_b = _frames(capture, **{"guided.tile": tile, "guided.device": "cpu"})
    assert np.array_equal(a, b)
    assert infos and infos[0].plan.device == "cpu" and "guided.device = auto" in infos[0].plan.reasons["device"]
    assert all(i.device in ("", "cpu") for i in infos_b)
    assert "device" in str(infos[0].plan)


def test_the_torch_alignment_makes_the_numpy_pooling_decisions(capture, monkeypatch):
    """What a GPU runs (spikeview.guided.temporal._align_torch), run on the CPU: identical pooling."""
    from spikeview.cfa import parse_cfa
    from spikeview.guided import temporal

    for centre in (35, 45):
        a, b = centre - 5, centre + 5
        tot0, p0 = temporal.pool_counts(capture, a, b, 3, parse_cfa(capture.cfa))
        monkeypatch.setattr(temporal, "TORCH_ON_CPU", True)
        tot1, p1 = temporal.pool_counts(capture, a, b, 3, parse_cfa(capture.cfa))
        monkeypatch.setattr(temporal, "TORCH_ON_CPU", False)
        assert np.array_equal(tot0, tot1) and np.array_equal(p0.dtau, p1.dtau)
        assert p0.reason == p1.reason and set(p0.shifts) == set(p1.shifts)
        for k in p0.shifts:
            assert np.array_equal(p0.shifts[k], p1.shifts[k]) and np.array_equal(p0.accepted[k], p1.accepted[k])
    assert p0.dtau.max() > 10  # something was pooled: the comparison is not of two empty maps


@pytest.mark.parametrize("cores", [2, 64])
def test_a_sequence_built_windows_ahead_gives_the_same_frames(capture, monkeypatch, cores):
    """The GPU path prepares the next windows in threads (half the host's cores, 2 to 8) while this one samples: the
    same frames, in order."""
    import os

    from spikeview.guided import video

    a, _ = _frames(capture)
    monkeypatch.setattr(video, "_on_gpu", lambda p: True)
    monkeypatch.setattr(os, "cpu_count", lambda: cores)
    assert video.prefetch_depth() == (video.PREFETCH if cores == 2 else video.PREFETCH_MAX)
    b, _ = _frames(capture)
    assert np.array_equal(a, b)


def test_tensors_on_another_device_raise_instead_of_being_copied():
    from spikeview.guided.priors.ffdnet import FFDNetDenoiser

    net = FFDNetDenoiser(color=True, pretrained=False, generator=torch.Generator().manual_seed(0))
    with pytest.raises(ParameterError, match="is on meta but this FFDNet's weights are on cpu"):
        net(torch.zeros(1, 3, 8, 8, device="meta"), 0.1)


def test_the_data_term_keeps_every_tensor_on_its_device(capture):
    """The data term and its operators on another device (torch's shape-only 'meta' device stands in for a
    GPU): a tensor made on the CPU inside prox or the forward model would raise here."""
    from spikeview.guided.observation import Observation
    from spikeview.guided.plan import make_plan
    from spikeview.guided.sampler import GuidedSampler

    p = GuidedConfig()
    obs = Observation.from_source(capture, 45, 10, alpha=None if capture.cfa is None else [1.0, 1.0, 1.0], eta=2.0, radius=0)
    plan = make_plan(obs, p)
    data = GuidedSampler.data_term(obs, plan, p, torch.device("meta"))
    c = 3 if plan.mosaic else 1
    z = torch.zeros(1, c, *obs.shape, device="meta")
    out = data.prox(z, torch.full((1, c, 1, 1), 0.5, device="meta"), 1)
    assert out.device.type == "meta" and out.shape == z.shape


def test_precision_on_a_gpu_is_float32_tf32_unless_bfloat16_is_asked_for():
    from spikeview.guided.precision import resolve_precision

    cuda = torch.device("cuda", 0)  # a device object needs no GPU
    assert resolve_precision("auto", device=cuda)[0] == "float32"
    assert "TF32" in resolve_precision("auto", device=cuda)[1]
    assert resolve_precision("float32-fast", device=cuda)[0] == "float32"
    assert resolve_precision("bfloat16-mixed", device=cuda)[0] == "bfloat16-mixed"


def test_a_dask_worker_keeps_the_recipe_without_several_gpus():
    from spikeview.cluster.run import _worker_recipe

    r = {"run": {"method": "guided"}, "guided": {"device": "auto"}}
    assert _worker_recipe(r, in_worker=False) is r
    assert _worker_recipe(r, in_worker=True) is r  # fewer than two GPUs here: nothing to place


@pytest.mark.filterwarnings("ignore::spikeview.classical.colour_cast.ColourCastWarning")  # a 1-wide Bayer has no B site
@pytest.mark.parametrize("cfa", ["RGGB", "none"])
@pytest.mark.parametrize("shape", [(1, 1), (1, 8), (8, 1)])
def test_a_capture_too_small_for_guided_gets_one_sentence(tmp_path, capsys, cfa, shape):
    """A 1×1 or 1×N capture once ended in "unexpected ValueError … (this is a bug …)" in the pooling's alignment."""
    from spikeview.cli.main import main

    path = tmp_path / "c.npy"
    np.save(path, (np.random.default_rng(0).random((60, *shape)) < 0.4).astype(np.uint8))
    rc = main(["reconstruct", str(path), "--cfa", cfa, "--method", "guided", "--at", "30", "--out", str(tmp_path / "o.npy")])
    err = capsys.readouterr().err
    assert rc != 0 and "this is a bug" not in err and "needs at least 2x2; use --method tfp" in err
    assert not (tmp_path / "o.npy").exists()


@pytest.mark.parametrize("cfa", ["RGGB", None], ids=["bayer", "mono"])
def test_the_device_arrays_give_numpys_sums_and_variances(cfa):
    """The pooling's per-photosite arrays on a device (spikeview.guided.temporal._box_torch, _interp_torch): the same
    float32/float64 roundings as scipy's 3×3 sums and numpy's interpolation, bit for bit on the CPU."""
    import torch

    from spikeview.guided import temporal

    rng = np.random.default_rng(1)
    for shape in ((64, 48), (65, 47), (2, 9)):
        for x in (rng.integers(0, 40, shape).astype(np.float32), (rng.random(shape) * 37 / 3).astype(np.float32)):
            a = temporal._box_same_colour(x, cfa)
            b = temporal._box_same_colour(torch.from_numpy(x), cfa).numpy()
            assert b.dtype == a.dtype and np.array_equal(a, b)
    curve = (np.array([1.0, 3.0, 7.0, 7.0, 20.0]), np.array([0.5, 0.6, 0.9, 1.0, 1.2]))  # a repeated level too
    g = np.concatenate([rng.random(5000) * 30, [0.0, 1.0, 3.0, 7.0, 20.0, 25.0]]).astype(np.float32)
    for scale in (1.0, 4.0 / 9.0):
        a = temporal._countvar(g, 40.0, curve, scale)
        b = temporal._countvar(torch.from_numpy(g), 40.0, curve, scale).numpy()
        assert b.dtype == np.float32 and np.array_equal(a, b)


@pytest.mark.parametrize("cfa", ["RGGB", "none"])
def test_a_panning_and_a_dark_capture_pool_alike_on_the_device_path(cfa, monkeypatch):
    """The gather at each tile's shift (a pan) and the low-light extension after the device stage: the same pooled
    counts, support and decisions as numpy."""
    from scipy.ndimage import gaussian_filter

    from spikeview.cfa import parse_cfa
    from spikeview.guided import temporal
    from spikeview.io.source import ArraySource
    from spikeview.sim import SimConfig, demo_scene, simulate

    rng = np.random.default_rng(4)
    tex = gaussian_filter(rng.random((64, 160)), 2.0)
    tex = 0.1 + 0.8 * (tex - tex.min()) / (tex.max() - tex.min())
    rates = np.stack([tex[:, int(round(0.2 * t)):int(round(0.2 * t)) + 64] for t in range(90)]) * 0.6  # 2 px a window
    pan = ArraySource((rng.random(rates.shape) < rates).astype(np.uint8), cfa=None if cfa == "none" else cfa)
    dark = simulate(demo_scene(size=64, seed=1), SimConfig(n_ticks=200, width=64, height=64, cfa=cfa, seed=6, rate=0.03))
    moved = extended = False
    for src, centre in ((pan, 45), (dark, 100)):
        a, b = centre - 5, centre + 5
        tot0, p0 = temporal.pool_counts(src, a, b, 2, parse_cfa(src.cfa))
        monkeypatch.setattr(temporal, "TORCH_ON_CPU", True)
        tot1, p1 = temporal.pool_counts(src, a, b, 2, parse_cfa(src.cfa))
        monkeypatch.setattr(temporal, "TORCH_ON_CPU", False)
        assert np.array_equal(tot0, tot1) and np.array_equal(p0.dtau, p1.dtau) and p0.reason == p1.reason
        assert all(np.array_equal(x, y) for x, y in zip(p0.support, p1.support, strict=True))
        moved |= any(np.any(s != 0) for s in p0.shifts.values())
        extended |= bool(p0.extended)
    assert moved and extended  # tiles read at a shift (the gather), and the dark capture pooled beyond ±radius
