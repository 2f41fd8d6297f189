"""Rejected candidates for issue 15: cheaper high-noise prior calls where bfloat16 does not pay.

On an Intel Xeon without AMX (benchmarks/results/prior_xeon.md) a bfloat16 layer takes 1.8x float32's time,
so ``auto`` runs float32 there. Two other ways to spend less on the high-noise steps were measured on the bench:

* ``coarse``: the noisy image 2x2-averaged (its noise halves), denoised by FFDNet at σ/2 (a quarter of the work),
  upsampled (bilinear or bicubic);
* ``int8``: the hidden layers in int8 (oneDNN's VNNI convolution via ``torch.ao``: a 1000² layer 0.028 s against
  float32's 0.148 s here, 5.2x), weights per output channel, activations per tensor with scales from the pass's
  own 9 patches of 64×64 (their maximum, or a quantile), optionally with cross-layer equalisation of the channels
  (Nagel et al. 2019; ReLU commutes with positive per-channel scales). First and last layers float32.

Scored like ``bench_prior.py --quality``: Δ against float32 on the same windows of the held-out bench scenes
(gain-fitted PSNR/SSIM, data_range 1); budget -0.1 dB / -0.005 SSIM on every scene.

Measured (2026-11-26, 256², 8 held-out scenes × 2 windows, Intel Xeon; 214 s), worst scene per candidate:

| candidate | ΔPSNR worst | ΔSSIM worst | within budget |
|---|---|---|---|
| coarse bilinear, σ ≥ 45/255 (1 of 6 steps) | -0.962 (page_bright) | -0.0118 (immunohistochemistry) | no |
| coarse bicubic, σ ≥ 45/255 | -0.647 (page_bright) | -0.0066 (immunohistochemistry) | no |
| coarse bicubic, σ ≥ 30/255 (2 steps) | -1.284 (page_bright) | -0.0174 (immunohistochemistry) | no |
| int8 max, σ ≥ 45/255 | -0.295 (colorwheel) | -0.0102 (colorwheel) | no |
| int8 max, σ ≥ 30/255 | -0.108 (astronaut_dark) | -0.0087 (astronaut_dark) | no |
| int8 q99.99 equalised, σ ≥ 45/255 | -0.087 (astronaut_dark) | -0.0048 (rocket_lamps) | yes, by 0.0002 SSIM |
| int8 q99.99 equalised, σ ≥ 30/255 | -0.082 (astronaut_dark) | -0.0165 (colorwheel) | no |

(More steps are worse in every family.) The one candidate inside the budget saves one step of six at ~0.3 s
instead of 1.35 s a 1000² pass (~12 % of the frame), is inside by 0.0002 SSIM on 16 windows (int8 max on the
same step is -0.0102), and runs on torch's quantized tensors, which torch 2.13 marks deprecated: not offered
to ``auto``.

    python benchmarks/bench_step_candidates.py [--size 256] [--windows 2] [--only coarse|int8]
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import torch
import torch.nn.functional as F

from spikeview.bench.data import SCENES, TUNE_SCENES, make_cases
from spikeview.bench.guided import Sequence, score
from spikeview.guided import precision as prec
from spikeview.guided.config import GuidedConfig
from spikeview.guided.priors.ffdnet import _conv_fused, _pack
from spikeview.guided.sampler import GuidedSampler, load_prior


class Coarse:
    """The prior at half resolution: ``up(D(avgpool2(x), σ/2))``."""

    def __init__(self, prior, up: str):
        self.prior, self.up = prior, up
        self.channels, self.sigma_max = prior.channels, prior.sigma_max

    def denoise(self, x, sigma):
        h, w = x.shape[-2:]
        ph, pw = h % 2, w % 2
        xp = F.pad(x, (0, pw, 0, ph), mode="replicate") if (ph or pw) else x
        s = sigma
        if isinstance(s, torch.Tensor) and s.ndim == 4:  # a per-pixel map: the RMS of each 2×2 block, halved
            v = F.pad(s * s, (0, pw, 0, ph), mode="replicate") if (ph or pw) else s * s
            s = F.avg_pool2d(v, 2).sqrt() / 2
        else:
            s = s / 2
        y = self.prior.denoise(F.avg_pool2d(xp, 2), s)
        return F.interpolate(y, scale_factor=2, mode=self.up, align_corners=False)[..., :h, :w]


class Int8:
    """FFDNet with int8 hidden layers (see the module docstring)."""

    def __init__(self, net, quantile: float | None, equalise: bool):
        import torch.ao.nn.intrinsic.quantized as nniq

        self.net, self.quantile = net, quantile
        self.channels, self.sigma_max = net.channels, net.sigma_max
        W = [w.detach().float().clone() for w in net.weight]
        B = [b.detach().float().clone() for b in net.bias]
        if equalise:  # per-channel scales s: layer i's output channel c / s_c, layer i+1's input channel c × s_c
            g = torch.Generator().manual_seed(1)
            img = F.interpolate(torch.rand(1, net.channels, 16, 16, generator=g), size=(128, 128), mode="bicubic",
                                align_corners=False).clamp(0, 1)
            f = torch.cat([torch.cat((net._noise_map(s / 255, x, (0, 0)), F.pixel_unshuffle(x, 2)), 1)
                           for s in (15, 25, 50) for x in [img + s / 255 * torch.randn(img.shape, generator=g)]], 0)
            for i in range(len(W) - 2):
                f = F.relu(F.conv2d(f, W[i], B[i], padding=1))
                r = f.amax(dim=(0, 2, 3)).clamp_min(1e-6)
                s = (r / W[i + 1].abs().amax(dim=(0, 2, 3)).clamp_min(1e-9)).sqrt()
                s = s / s.mean()
                W[i], B[i] = W[i] / s.view(-1, 1, 1, 1), B[i] / s
                W[i + 1] = W[i + 1] * s.view(1, -1, 1, 1)
                f = f / s.view(1, -1, 1, 1)
        self.W, self.B = W, B
        self.P = [_pack(w.contiguous(memory_format=torch.channels_last)) for w in W]
        self.convs = []
        for w, b in zip(W[1:-1], B[1:-1], strict=True):
            sc = (w.abs().amax(dim=(1, 2, 3)) / 127).clamp_min(1e-12).double()
            conv = nniq.ConvReLU2d(w.shape[1], w.shape[0], 3, padding=1)
            conv.set_weight_bias(torch.quantize_per_channel(w, sc, torch.zeros(w.shape[0], dtype=torch.long), 0, torch.qint8), b)
            self.convs.append(conv)

    def _ranges(self, feats):
        n, c, h, w = feats.shape
        p = 64
        ys, xs = [0, max(h // 2 - p // 2, 0), max(h - p, 0)], [0, max(w // 2 - p // 2, 0), max(w - p, 0)]
        f = torch.cat([feats[:, :, y:y + p, x:x + p] for y in ys for x in xs], 0).contiguous(memory_format=torch.channels_last)
        out = []
        for i in range(len(self.W) - 1):
            f = _conv_fused(f, self.P[i], self.B[i], True)
            flat = f.flatten()
            out.append(float(flat.max()) if self.quantile is None
                       else float(flat.topk(max(1, int(flat.numel() * (1 - self.quantile)))).values[-1]))
        return out

    def denoise(self, x, sigma):
        h, w = x.shape[-2:]
        ph, pw = h % 2, w % 2
        xp = F.pad(x, (0, pw, 0, ph), mode="reflect") if (ph or pw) else x
        feats = torch.cat((self.net._noise_map(sigma, x, (ph, pw)), F.pixel_unshuffle(xp, 2)), 1).float()
        feats = feats.contiguous(memory_format=torch.channels_last)
        r = self._ranges(feats)
        q = torch.quantize_per_tensor(_conv_fused(feats, self.P[0], self.B[0], True), max(r[0], 1e-6) / 255, 0, torch.quint8)
        for i, conv in enumerate(self.convs, start=1):
            conv.scale, conv.zero_point = max(r[i], 1e-6) / 255, 0
            q = conv(q)
        res = _conv_fused(q.dequantize().contiguous(memory_format=torch.channels_last), self.P[-1], self.B[-1], False)
        return (xp - F.pixel_shuffle(res.contiguous().to(x.dtype), 2))[..., :h, :w]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=256)
    ap.add_argument("--windows", type=int, default=2)
    ap.add_argument("--only", choices=["coarse", "int8"], default=None)
    a = ap.parse_args()
    prior = load_prior(GuidedConfig(), 3)
    smp = GuidedSampler(GuidedConfig(), prior=prior)
    wrappers = {}
    if a.only in (None, "coarse"):
        wrappers.update({"coarse bilinear": lambda: Coarse(prior, "bilinear"), "coarse bicubic": lambda: Coarse(prior, "bicubic")})
    if a.only in (None, "int8"):
        wrappers.update({"int8 max": lambda: Int8(prior, None, False), "int8 q99.99 equalised": lambda: Int8(prior, 0.9999, True)})
    cands = {f"{name}, σ ≥ {th:g}/255": (name, th / 255) for name in wrappers for th in (45, 30, 18)}
    made = {name: make() for name, make in wrappers.items()}
    state = {"c": None}
    real_at, real_steps = prec.at_precision, prec.step_precisions

    def at(prior_, p):
        return made[p.split(":", 1)[1]] if p.startswith("cand:") else real_at(prior_, p)

    def steps(precision, sigmas, layers=None, threshold=None):
        out = real_steps(precision, sigmas, layers, threshold)
        if state["c"] is None or isinstance(sigmas, (int, np.integer)):
            return out
        name, th = cands[state["c"]]
        return [f"cand:{name}" if s >= th else o for o, s in zip(out, np.asarray(sigmas).reshape(-1), strict=True)]

    prec.at_precision, prec.step_precisions = at, steps
    rows: dict[str, dict[str, list]] = {}
    t0 = time.time()
    try:
        for case in make_cases([n for n in SCENES if n not in TUNE_SCENES], size=a.size, frames=a.windows):
            obs = Sequence(case.source).observation(case.center)
            state["c"] = None
            f32 = score(smp.run(obs, GuidedConfig(precision="float32")), case.gt)
            for c in cands:
                state["c"] = c
                q = score(smp.run(obs, GuidedConfig(precision="float32")), case.gt)
                rows.setdefault(c, {}).setdefault(case.scene, []).append((q[0] - f32[0], q[1] - f32[1]))
            print(case.scene, flush=True)
    finally:
        prec.at_precision, prec.step_precisions = real_at, real_steps
    print(f"| candidate | ΔPSNR worst (scene) | ΔSSIM worst (scene) | within -0.1 dB / -0.005 |\n|---|---|---|---|")
    for c, per in rows.items():
        d = {sc: (float(np.mean([x for x, _ in v])), float(np.mean([y for _, y in v]))) for sc, v in per.items()}
        wa, wb = min(d, key=lambda k: d[k][0]), min(d, key=lambda k: d[k][1])
        ok = d[wa][0] >= -0.1 and d[wb][1] >= -0.005
        print(f"| {c} | {d[wa][0]:+.3f} ({wa}) | {d[wb][1]:+.4f} ({wb}) | {'yes' if ok else 'no'} |")
    print(f"{time.time() - t0:.0f} s")


if __name__ == "__main__":
    main()
