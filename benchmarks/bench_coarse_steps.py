"""Rejected candidate for issue 15: the high-noise prior calls at half resolution ("coarse" steps).

Where bfloat16 does not pay (an Intel Xeon without AMX: benchmarks/results/prior_xeon.md), the other way to
spend less on the high-noise steps is fewer pixels: the noisy image 2x2-averaged (its noise halves), denoised
by FFDNet at σ/2 (a quarter of the work), and upsampled. Scored like ``bench_prior.py --quality``: Δ against
float32 on the same windows of the held-out bench scenes (gain-fitted PSNR/SSIM, data_range 1), budget
-0.1 dB / -0.005 SSIM on every scene.

Measured (2026-11-26, 256², 2 windows a scene): even one coarse step (σ ≥ 45/255) costs -0.96 dB and -0.012
SSIM on page_bright (hubble_deep_field -0.40 dB, immunohistochemistry -0.012 SSIM; astronaut_dark gains +1.2 dB);
two or three steps -2.1 / -3.8 dB. Far over budget: not a candidate for ``auto``.

    python benchmarks/bench_coarse_steps.py [SIZE] [WINDOWS] [held|tune]
"""
import sys, time, numpy as np, torch, torch.nn.functional as F
from spikeview.bench.data import SCENES, TUNE_SCENES, make_cases
from spikeview.bench.guided import Sequence, score
from spikeview.guided import precision as prec
from spikeview.guided.config import GuidedConfig
from spikeview.guided.sampler import GuidedSampler, load_prior

size = int(sys.argv[1]) if len(sys.argv) > 1 else 256; frames = int(sys.argv[2]) if len(sys.argv) > 2 else 2; which = sys.argv[3] if len(sys.argv) > 3 else "held"
MODE = {"up": "bilinear"}
class Coarse:
    def __init__(self, prior, p):
        self.prior = prior if p == "float32" else prec.AtPrecision(prior, p)
        self.channels = prior.channels; self.sigma_max = prior.sigma_max
    def denoise(self, x, sigma):
        h, w = x.shape[-2:]; ph, pw = h % 2, w % 2
        xp = F.pad(x, (0, pw, 0, ph), mode="replicate") if (ph or pw) else x
        xd = F.avg_pool2d(xp, 2)
        s = sigma
        if isinstance(s, torch.Tensor) and s.ndim == 4:
            v = s * s
            if ph or pw: v = F.pad(v, (0, pw, 0, ph), mode="replicate")
            s = F.avg_pool2d(v, 2).sqrt() / 2
        else:
            s = s / 2
        yd = self.prior.denoise(xd, s)
        y = F.interpolate(yd, scale_factor=2, mode=MODE["up"], align_corners=False) if MODE["up"] != "bicubic" else F.interpolate(yd, scale_factor=2, mode="bicubic", align_corners=False)
        return y[..., :h, :w]
orig_at = prec.at_precision
def at(prior, p):
    if p.startswith("coarse:"):
        return Coarse(prior, p.split(":", 1)[1])
    return orig_at(prior, p)
prec.at_precision = at
import spikeview.guided.sampler as S; S.prec.at_precision = at
orig_sp = prec.step_precisions
TH = {"v": None}
def sp(precision, sigmas, layers=None, threshold=None):
    out = orig_sp(precision, sigmas, layers, threshold)
    if TH["v"] is None or isinstance(sigmas, (int, np.integer)): return out
    s = np.asarray(sigmas).reshape(-1)
    return [("coarse:" + o) if si >= TH["v"] else o for o, si in zip(out, s)]
prec.step_precisions = sp
held = [n for n in SCENES if n not in TUNE_SCENES] if which == "held" else list(TUNE_SCENES)
prior = load_prior(GuidedConfig(), 3)
smp = GuidedSampler(GuidedConfig(), prior=prior)
cands = {"coarse σ≥45 (1 step) bilinear": (45/255, "bilinear"), "coarse σ≥30 (2 steps) bilinear": (30/255, "bilinear"),
         "coarse σ≥30 bicubic": (30/255, "bicubic"), "coarse σ≥18 (3 steps) bilinear": (18/255, "bilinear")}
rows = {}
t0 = time.time()
for case in make_cases(held, size=size, frames=frames):
    obs = Sequence(case.source).observation(case.center)
    TH["v"] = None
    f32 = score(smp.run(obs, GuidedConfig(precision="float32")), case.gt)
    for name, (th, up) in cands.items():
        TH["v"] = th; MODE["up"] = up
        q = score(smp.run(obs, GuidedConfig(precision="float32")), case.gt)
        rows.setdefault(name, {}).setdefault(case.scene, []).append((q[0] - f32[0], q[1] - f32[1]))
    print(case.scene, f"{f32[0]:.2f}", {k: tuple(round(x, 4) for x in v[case.scene][-1]) for k, v in rows.items()}, flush=True)
for name, per in rows.items():
    d = {sc: (np.mean([a for a, _ in v]), np.mean([b for _, b in v])) for sc, v in per.items()}
    print(f"{name}: dPSNR mean {np.mean([a for a,_ in d.values()]):+.3f} worst {min(a for a,_ in d.values()):+.3f}; dSSIM mean {np.mean([b for _,b in d.values()]):+.4f} worst {min(b for _,b in d.values()):+.4f}")
print("took", time.time() - t0)
