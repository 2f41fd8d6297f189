"""Scores that a blur cannot win: real captures (no truth) and simulated low light (with truth).

Usage::

    spikeview bench --real uhsr.npz [MORE…]     # real captures: detail, patchiness, residual noise, NIQE
    spikeview bench --low-light                  # simulated static scenes at 3 light levels, mono and RGGB

**What runs is the CLI**: every frame is ``spikeview reconstruct FILE --method M --at T --transfer linear`` run as a
command (its defaults: the planner, the pooling, the exposure, the white point), read back from the ``.npy`` it writes.
Methods: TFP-10 (the window alone), TFI, and the guided default.

**Scores** (:mod:`spikeview.metrics`; NIQE: :mod:`spikeview.bench.niqe`):

* ``detail``: :func:`~spikeview.metrics.detail_kept`, the correlation of the band-pass (Gaussians of σ 1 and 3 px)
  of the frame with the reference's. A blur and noise both lower it; on the simulated scenes it ranks the truth
  first (1 by definition) and, at low light, TFI and the guided frame above TFP.
* ``patchiness``: :func:`~spikeview.metrics.patchiness`, the unevenness of the residual noise over the flat tiles
  (95th percentile over median of the high-pass spread; ~1 = evenly denoised): of the error against the truth on
  simulated scenes (the scene's texture cancels), of the frame itself on real captures.
* ``noise``: a no-reference residual noise level, the RMS of the finest diagonal Haar detail of the frame, in
  /255 of its white (the 99.5th percentile): what is left to see in a smooth region.
* ``NIQE``: the no-reference score of Mittal, Soundararajan and Bovik (2013; lower is better), with the release's
  pristine model (packaged: ``spikeview/bench/data``), on the frame as a viewer sees it (white at its 99.5th
  percentile, sRGB; the luma of a colour frame). Rows ``truth`` (simulated scenes, once per scene: a static scene's
  truth is the same at every light level) and ``long exposure`` (real captures: the reference) score NIQE alone, so
  the table shows whether the score ranks the truth first. Checked before relying on it (skimage's camera, coffee and
  astronaut at 256² and 512², and this bench): it ranks the truth first against Gaussian blurs (σ 0.7 to 3), Poisson
  noise (5 to 1000 photons at white) and every TFP, TFI and guided frame of every simulated scene here (256²: truth
  4.3 to 7.3, the best method 8.7 to 18.7; 512²: truth 3.1 and 4.4, the best method 5.6 to 10.8). Where it fails: (1)
  it reads whole 96×96 blocks only, so a 256² frame is scored on its top-left 192×192, 4 blocks, and is noisy (9 crops
  of one scene: 3.4 to 4.0); at 256² coffee's truth (7.0) scored worse than the same scene with Poisson noise then
  smoothed (5.0 to 5.5); (2) it prefers smooth to noisy and does not rank methods as PSNR and detail do: TFP beats TFI
  on coffee at 0.02 and 0.3 spikes per tick, the guided frame of the fast pan (detail 0.10, TFI 0.12) beats TFI by 11,
  and at 512² TFI beats the guided frame on coffee at 0.05; (3) a frame of isolated spikes (TFP on the real capture)
  is off its scale (~500); on the real capture the denoised frames beat the long exposure, which keeps its own noise.
  Read it beside ``detail`` and ``noise``, never alone.
* with truth: PSNR after ONE global gain (:func:`~spikeview.metrics.colour_scores`), the frame against the
  clean linear frame at the window's centre.

The reference of a real capture is its **long exposure**: the methods reconstruct the middle of the capture's
first 45 % from that part alone, and the reference is the mean rate of its last 45 %, moved back by the frame's
measured drift to the scored tick (:func:`drift_compensated_mean`; the real dark capture drifts 5 px over its 200
ticks, so an uncompensated reference was blurred and displaced, and rewarded a blur) — the same scene with
independent noise; the mean of the ticks around a window would share spikes with a method that
pools them, and the counts of adjacent spans anti-correlate for a regularly firing pixel). The reference's own
noise lowers every method's ``detail`` by the same factor: compare methods, not captures. It carries the
sensor's fixed pattern, which TFP shares and a denoiser removes, so it favours TFP-like frames a little: read
``detail`` beside ``noise``; NIQE needs no reference at all, but see its caveats above.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np

#: the methods scored, as ``spikeview reconstruct --method`` names them
METHODS = ("tfp", "tfi", "guided")
#: the rows that score a reference itself (NIQE only): a simulated scene's truth, a real capture's long exposure
TRUTH, REFERENCE = "truth", "long exposure"
#: simulated light levels (mean spikes per tick of a mid-gray) of ``--low-light``
LIGHT_LEVELS = (0.02, 0.05, 0.3)
#: ... and pans (pixels per second at 20 kHz: 400 = 0.2 px a 10-tick window, slow; 2000 = 1 px a window) at 0.03
PANS = (400.0, 2000.0)


def residual_noise(x: np.ndarray) -> float:
    """RMS of the finest diagonal Haar detail of ``x`` (luminance), in /255 of its 99.5th percentile: a no-reference
    estimate of the noise left in a frame (the finest diagonal detail of a natural image is mostly noise; a robust
    median would read 0 on a sparse frame of isolated spikes)."""
    a = np.asarray(x, dtype=np.float64)
    a = a.mean(axis=-1) if a.ndim == 3 else a
    h2, w2 = (a.shape[0] // 2) * 2, (a.shape[1] // 2) * 2
    p = a[:h2, :w2]
    hh = (p[0::2, 0::2] - p[0::2, 1::2] - p[1::2, 0::2] + p[1::2, 1::2]) / 2.0
    white = float(np.quantile(a, 0.995))
    return 255.0 * float(np.sqrt(np.mean(hh * hh))) / max(white, 1e-9)


def _spikeview(*argv: str) -> None:
    """``spikeview ARGV…`` in a child process (the command line a user types; the bench does not import the CLI)."""
    import subprocess
    import sys

    from spikeview.errors import ParameterError

    r = subprocess.run([sys.executable, "-m", "spikeview", *argv], capture_output=True, text=True)
    if r.returncode != 0:  # the command's own sentence, not a traceback
        said = r.stderr.strip().splitlines()[-1] if r.stderr.strip() else f"exit status {r.returncode}"
        raise ParameterError(f"spikeview {' '.join(argv[:2])} failed: {said.removeprefix('spikeview: error: ')}")


def _reconstruct(path: str, method: str, at: int, out: Path, extra: list[str] | None = None) -> np.ndarray:
    """``spikeview reconstruct PATH --method METHOD --at AT --transfer linear`` (its defaults otherwise)."""
    dest = out / f"{Path(path).stem}_{method}_{at}.npy"
    _spikeview("reconstruct", path, "--method", method, "--at", str(at), "--transfer", "linear", "--out", str(dest),
               "--overwrite", *(extra or []))
    return np.squeeze(np.load(dest)).astype(np.float64)


def no_reference(x: np.ndarray) -> float:
    """NIQE of a linear frame (:func:`spikeview.bench.niqe.niqe`, lower is better); NaN for a frame it cannot score
    (under 96×96 pixels, or without two textured 96×96 blocks): the table prints "—"."""
    from spikeview.bench.niqe import niqe
    from spikeview.errors import ParameterError

    try:
        return niqe(x)
    except ParameterError:
        return float("nan")


def score_frame(x: np.ndarray, ref: np.ndarray, truth: bool) -> dict[str, float]:
    from spikeview.metrics import colour_scores, detail_kept, patchiness

    r = ref / max(float(np.quantile(ref, 0.999)), 1e-9)
    out = {"detail": detail_kept(x, r), "patchiness": patchiness(x, r, truth=truth), "noise": residual_noise(x),
           "niqe": no_reference(x)}
    if truth:
        c = colour_scores(x, np.clip(r, 0.0, 1.0) if x.ndim == r.ndim else np.clip(r.mean(axis=-1), 0, 1))
        out["psnr"] = c["psnr_1gain"]
        if x.ndim == 3:  # colour: ΔE00 and the white-balance angle (issue 26); a gray frame has neither ("—")
            out["delta_e00"], out["wb_angle"] = c["delta_e00"], c["wb_angle"]
    return out


#: a real capture's ticks: methods read the first 45 %, the reference is the mean of the last 45 % (the gap between:
#: a regularly firing pixel's counts over adjacent spans anti-correlate, through the phase at their common edge)
REAL_SPLIT = (0.45, 0.55)


#: ticks per slice of the reference when it follows a drift (:func:`drift_compensated_mean`)
REF_SLICE = 10


def drift_compensated_mean(src, a0: int, a1: int, b0: int, b1: int, at: int) -> np.ndarray:
    """The mean rate of ticks ``[b0, b1)`` as the scene stood at tick ``at``: the frame's drift (px per tick) is measured
    between the means of ``[a0, a1)`` and ``[b0, b1)`` (:func:`spikeview.guided.temporal.frame_drift`, the whole frame),
    and each :data:`REF_SLICE`-tick slice is moved back by it before the mean (bilinear, sub-pixel). A capture whose
    scene drifts (the real dark one: 0.036 px a tick, 5 px over the capture) would otherwise be scored against a
    reference blurred and displaced by that drift, which rewards a blur."""
    from scipy.ndimage import shift as nd_shift

    from spikeview.guided.temporal import frame_drift

    first = np.asarray(src.read(a0, a1), dtype=np.float64).mean(axis=0)
    late = np.asarray(src.read(b0, b1), dtype=np.float64)
    d = frame_drift(first, late.mean(axis=0))
    span = (b0 + b1) / 2.0 - (a0 + a1) / 2.0
    if d is None or span <= 0 or float(np.hypot(*d)) < 0.5:
        return late.mean(axis=0)
    vy, vx = d[0] / span, d[1] / span
    out = np.zeros(late.shape[1:], np.float64)
    for t in range(0, late.shape[0], REF_SLICE):
        part = late[t:t + REF_SLICE].sum(axis=0)
        dt = b0 + t + min(REF_SLICE, late.shape[0] - t) / 2.0 - at
        out += nd_shift(part, (-vy * dt, -vx * dt), order=1, mode="nearest")
    return out / late.shape[0]


def run_real(files: list[str]) -> list[dict]:
    """Every method on the first part of every real capture (:data:`REAL_SPLIT`), at its middle tick, scored against
    the mean rate of the last part (the reference shares no spike with anything a method may read)."""
    from spikeview.io import open_source

    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        t = Path(tmp)
        for f in files:
            src = open_source(f)
            n = int(src.n_frames)
            half, rest = int(REAL_SPLIT[0] * n), int(REAL_SPLIT[1] * n)
            first = t / f"{Path(f).stem}_first_part.npy"
            np.save(first, np.asarray(src.read(0, half), dtype=np.uint8))
            ref = drift_compensated_mean(src, 0, half, rest, n, half // 2)
            cfa = ["--cfa", src.cfa if src.cfa else "none"]
            at = half // 2
            for m in METHODS:
                x = _reconstruct(str(first), m, at, t, cfa)
                rows.append({"capture": os.path.basename(f), "tick": at, "method": m, **score_frame(x, ref, False)})
            # the reference itself (NIQE only: the other scores are measured against it)
            rows.append({"capture": os.path.basename(f), "tick": at, "method": REFERENCE, "niqe": no_reference(ref)})
    return rows


def run_low_light(size: int = 256, ticks: int = 400) -> list[dict]:
    """Simulated scenes (camera mono and RGGB, coffee RGGB), static at :data:`LIGHT_LEVELS` and panning (:data:`PANS`) at
    0.03 spikes per tick, scored against their truth."""
    import skimage.data
    from PIL import Image

    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        t = Path(tmp)
        Image.fromarray(skimage.data.camera()).save(t / "camera.png")
        Image.fromarray(skimage.data.coffee()[:400, 100:500]).save(t / "coffee.png")
        static = (("camera", "none"), ("camera", "RGGB"), ("coffee", "RGGB"))  # a gray scene in colour too: its tint
        runs = [(scene, cfa, rate, 0.0) for scene, cfa in static for rate in LIGHT_LEVELS]
        runs += [(scene, cfa, 0.03, pan) for pan in PANS for scene, cfa in (("camera", "none"), ("coffee", "RGGB"))]
        truth_scored = set()
        for scene, cfa, rate, pan in runs:
            cap = t / f"{scene}_{cfa}_{rate}_{pan:g}.dat"
            _spikeview("simulate", str(t / f"{scene}.png"), "--ticks", str(ticks), "--cfa", cfa, "--rate", str(rate),
                       "--width", str(size), "--height", str(size), "--pan", f"{pan:g}", "0", "--out", str(cap),
                       "--overwrite")
            g = np.load(str(cap).replace(".dat", ".gt.npz"))
            at = ticks // 2
            i = int(np.argmin(np.abs(g["ticks"] - at)))
            truth = g["frames"][i].astype(np.float64)
            truth = truth.mean(axis=-1) if cfa == "none" else truth
            moving = f", pan {pan / 20000:g} px/tick" if pan else ""
            if (scene, cfa, pan) not in truth_scored:  # the truth once per scene (a static scene's is the same at every light)
                truth_scored.add((scene, cfa, pan))
                light = f"{rate:g}/tick" if pan else "every light level"
                rows.append({"capture": f"{scene} {cfa} {light}{moving}", "tick": at, "method": TRUTH,
                             "niqe": no_reference(truth)})
            for m in METHODS:
                x = _reconstruct(str(cap), m, at, t)
                rows.append({"capture": f"{scene} {cfa} {rate:g}/tick{moving}", "tick": at, "method": m,
                             **score_frame(x, truth, True)})
    return rows


def report(rows: list[dict], title: str) -> str:
    """A markdown table of ``rows``; a row without a score (the truth, the long exposure: NIQE only) prints "—"."""
    truth = any("psnr" in r for r in rows)
    cols = ([("psnr", "PSNR (1 gain)", "{:.2f}"), ("delta_e00", "ΔE00", "{:.1f}"), ("wb_angle", "WB", "{:.1f}°")]
            if truth else []) + [
        ("detail", "detail", "{:.3f}"), ("patchiness", "patchiness", "{:.2f}"), ("noise", "residual noise /255", "{:.1f}"),
        ("niqe", "NIQE (lower is better)", "{:.2f}")]
    head = "| capture | method | " + " | ".join(c[1] for c in cols) + " |"
    lines = [f"### {title}", "", head, "|" + "---|" * (len(cols) + 2)]
    for r in rows:
        cells = [fmt.format(r[k]) if k in r and np.isfinite(r[k]) else "—" for k, _, fmt in cols]
        lines.append(f"| {r['capture']} (tick {r['tick']}) | {r['method']} | " + " | ".join(cells) + " |")
    return "\n".join(lines)
