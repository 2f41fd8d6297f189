"""The comparison job (issue 27): classical frames scored as the guided runs are, ROI included; one global gain for
the colour scores (spikeview.metrics.colour_scores)."""

from __future__ import annotations

import functools
import threading

import numpy as np
import pytest

from spikeview.session import core, jobs


class _Ctx:
    def __init__(self):
        self.cancelled = threading.Event()
        self.state: dict = {}

    def report(self, payload):
        pass

    def check(self):
        pass


@functools.cache
def _capture():
    from spikeview.sim.demo import demo_capture

    return demo_capture(size=32, n_ticks=60, seed=5)


def _request(roi=None, truth=True):
    from spikeview.session.model import Session

    cap = _capture()
    st = core.memory_stream(cap, "compare", cap.gt_at if truth else None)
    s = Session()
    s.open_stream(st)
    params = dict(s.params, transfer="srgb")
    return jobs.CompareRequest(st.source, 30, params, None, roi, st.ground_truth, s.recipe(), ("tfp", "tfi"))


def test_score_frame_is_psnr_ssim_at_the_exposure_and_the_colour_scores():
    from spikeview import metrics

    rng = np.random.default_rng(0)
    gt = rng.uniform(0.1, 0.9, (16, 16, 3)).astype(np.float32)
    img = (gt * 2.0).astype(np.float32)  # linear-frame units twice the exposed ones
    s = jobs.score_frame(img, gt, 0.5)
    assert s["psnr"] == 100.0 and s["ssim"] == pytest.approx(1.0) and s["delta_e00"] == pytest.approx(0.0, abs=1e-6)
    cast = img * np.array([1.0, 1.0, 0.8], np.float32)  # a blue deficit: the one global gain cannot hide it
    c = jobs.score_frame(cast, gt, 0.5)
    assert c["delta_e00"] > 1.0 and c["psnr_1gain"] == pytest.approx(metrics.colour_scores(np.clip(cast * 0.5, 0, 1), gt)["psnr_1gain"])
    assert jobs.score_frame(img, None, 0.5) == {} and jobs.score_frame(img[:8], gt, 0.5) == {}


def test_compare_job_scores_tfp_and_tfi_on_the_frame_and_on_an_roi():
    v = jobs.compare_job(_request(), _Ctx())
    assert v.origin == (0, 0) and v.truth.shape == (32, 32, 3) and set(v.images) == {"tfp", "tfi"}
    for m in ("tfp", "tfi"):
        assert 10 < v.scores[m]["psnr"] < 60 and 0 < v.scores[m]["ssim"] <= 1 and v.scores[m]["delta_e00"] > 0
    r = jobs.compare_job(_request(roi=(9, 5, 16, 16)), _Ctx())
    assert r.origin == (8, 4)  # the crop starts on even pixels (the CFA phase), as every ROI job's
    assert r.truth.shape == (17, 17, 3) and r.images["tfp"].shape == (17, 17, 3) and "psnr" in r.scores["tfp"]
    n = jobs.compare_job(_request(truth=False), _Ctx())
    assert n.truth is None and n.scores == {"tfp": {}, "tfi": {}}


def test_roi_origin_follows_crop_roi():
    assert core.roi_origin(None, (10, 10)) == (0, 0)
    assert core.roi_origin((3, 5, 4, 4), (10, 10)) == (2, 4)


def test_load_ground_truth_reads_8_and_16_bit_images_and_refuses_another_size(tmp_path):
    from PIL import Image

    from spikeview.errors import ParameterError

    rgb = np.zeros((4, 6, 3), np.uint8)
    rgb[..., 0] = 255
    Image.fromarray(rgb).save(tmp_path / "rgb.png")
    colour = core.load_ground_truth(tmp_path / "rgb.png", (4, 6), colour=True)
    assert colour.shape == (4, 6, 3) and colour[0, 0].tolist() == [1.0, 0.0, 0.0]  # linear values / 255, as the bench
    mono = core.load_ground_truth(tmp_path / "rgb.png", (4, 6), colour=False)
    assert mono.shape == (4, 6) and mono[0, 0] == pytest.approx(1 / 3)
    deep = np.full((4, 6), 32768, np.uint16)
    Image.fromarray(deep).save(tmp_path / "deep.png")
    assert core.load_ground_truth(tmp_path / "deep.png", (4, 6), colour=False)[0, 0] == pytest.approx(32768 / 65535)
    with pytest.raises(ParameterError, match="rgb.png is 6×4 but the capture is 8×8"):
        core.load_ground_truth(tmp_path / "rgb.png", (8, 8), colour=True)
    (tmp_path / "bad.png").write_bytes(b"not an image")
    with pytest.raises(ParameterError, match="Cannot read bad.png as an image"):
        core.load_ground_truth(tmp_path / "bad.png", (4, 6), colour=True)


@pytest.mark.parametrize("cfa", ["none", "RGGB"])
def test_scores_do_not_depend_on_the_capture_s_rate_scale(cfa):
    """A capture is scored with its white point at the sampler's exposure level, so the same scene at half the rate
    scores alike (monochrome was scored in spikes per tick with a data range of 1: a Spike-Zoo clip, white 0.6 spikes
    per tick, 4.4 dB above its exported frames, and a capture at half the rate 6 dB above that)."""
    from spikeview.guided.observation import EXPOSURE_LEVEL
    from spikeview.session.model import Session
    from spikeview.sim.demo import demo_capture

    tfp = {}
    for rate in (0.6, 0.3):
        cap = demo_capture(size=32, n_ticks=60, seed=5, cfa=cfa, rate=rate)
        st = core.memory_stream(cap, "compare", cap.gt_at)
        s = Session()
        s.open_stream(st)
        req = jobs.CompareRequest(st.source, 30, dict(s.params, transfer="srgb"), None, None, st.ground_truth,
                                  s.recipe(), ("tfp",))
        v = jobs.compare_job(req, _Ctx())
        tfp[rate] = v.scores["tfp"]["psnr_1gain"]
        state = jobs.sequence_state(st.source, s.recipe().with_values({"run.method": "guided"}), None, _Ctx())
        k, _ = jobs.scoring_units(state, None)
        if cfa == "none":
            assert float(k) * float(state.sampler_white) == pytest.approx(EXPOSURE_LEVEL, rel=1e-5)
            # the display's White control does not move a score (the units come from the sequence's state alone)
            req2 = jobs.CompareRequest(st.source, 30, dict(s.params, transfer="srgb", white=0.05), None, None,
                                       st.ground_truth, s.recipe().with_values({"export.white": 0.05}), ("tfp",))
            assert jobs.compare_job(req2, _Ctx()).scores["tfp"]["psnr_1gain"] == pytest.approx(tfp[rate], abs=1e-6)
    assert abs(tfp[0.6] - tfp[0.3]) < 3.5, tfp  # the noise of half the spikes: 2.2 dB in colour
