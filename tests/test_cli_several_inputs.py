"""``spikeview reconstruct`` with several inputs or a folder: one output per input, the same settings, a bad input
said in one sentence while the others are written (issue 27). Monochrome and Bayer."""

from __future__ import annotations

import numpy as np
import pytest

from spikeview.cli.main import main


@pytest.mark.parametrize("cfa", ["none", "RGGB"])
def test_a_folder_and_a_list_of_inputs_give_one_output_each(tmp_path, capsys, cfa):
    rng = np.random.default_rng(0)
    src = tmp_path / "in"
    src.mkdir()
    for n in ("a", "b"):
        np.save(src / f"{n}.npy", (rng.random((60, 32, 32)) < 0.3).astype(np.uint8))
    out = tmp_path / "out"
    out.mkdir()
    assert main(["reconstruct", str(src), "--cfa", cfa, "--method", "tfp", "--at", "30", "--out", str(out)]) == 0
    assert sorted(p.name for p in out.glob("*.exr")) == ["a_tfp_t30.exr", "b_tfp_t30.exr"]
    one = tmp_path / "one.npy"
    assert main(["reconstruct", str(src / "a.npy"), "--cfa", cfa, "--method", "tfp", "--at", "30", "--out", str(one)]) == 0
    import OpenImageIO as oiio

    a = oiio.ImageBuf(str(out / "a_tfp_t30.exr")).get_pixels(oiio.FLOAT)
    alone = tmp_path / "alone.exr"
    assert main(["reconstruct", str(src / "a.npy"), "--cfa", cfa, "--method", "tfp", "--at", "30", "--out", str(alone)]) == 0
    assert np.array_equal(a, oiio.ImageBuf(str(alone)).get_pixels(oiio.FLOAT))  # the same input alone: the same pixels
    assert np.squeeze(np.load(one)).shape[:2] == (32, 32)
    capsys.readouterr()
    (src / "bad.npy").write_bytes(b"garbage")
    again = tmp_path / "again"
    again.mkdir()
    assert main(["reconstruct", str(src / "a.npy"), str(src / "bad.npy"), str(src / "b.npy"), "--cfa", cfa,
                 "--method", "tfp", "--at", "30", "--out", str(again)]) == 1
    err = capsys.readouterr().err
    assert "1 of 3 inputs failed" in err and "bad.npy" in err and "Traceback" not in err
    assert sorted(p.name for p in again.glob("*.exr")) == ["a_tfp_t30.exr", "b_tfp_t30.exr"]


def test_several_inputs_need_an_existing_folder_for_out(tmp_path, capsys):
    rng = np.random.default_rng(1)
    for n in ("a", "b"):
        np.save(tmp_path / f"{n}.npy", (rng.random((30, 16, 16)) < 0.3).astype(np.uint8))
    rc = main(["reconstruct", str(tmp_path / "a.npy"), str(tmp_path / "b.npy"), "--cfa", "none", "--at", "15",
               "--out", str(tmp_path / "missing")])
    assert rc == 1 and "names an existing folder" in capsys.readouterr().err
    assert not (tmp_path / "missing").exists()


@pytest.mark.parametrize("cfa", ["none", "RGGB"])
def test_captures_of_one_name_from_two_folders_and_a_profile_s_maps_in_a_folder(tmp_path, capsys, cfa):
    """Two folders' ``x.npy``: each output takes its folder's name (the second had collided with the first); a camera
    profile's maps (``cam.npz`` beside ``cam.toml``) in an input folder are not read as a capture; every input failing
    is said as such."""
    rng = np.random.default_rng(2)
    for d in ("m1", "m2"):
        (tmp_path / d).mkdir()
        np.save(tmp_path / d / "x.npy", (rng.random((40, 16, 16)) < 0.3).astype(np.uint8))
    out = tmp_path / "out"
    out.mkdir()
    assert main(["reconstruct", str(tmp_path / "m1" / "x.npy"), str(tmp_path / "m2" / "x.npy"), "--cfa", cfa,
                 "--at", "20", "--out", str(out)]) == 0
    assert sorted(p.name for p in out.glob("*.exr")) == ["m1_x_tfp_t20.exr", "m2_x_tfp_t20.exr"]
    np.savez(tmp_path / "m2" / "x.npz", spikes=(rng.random((40, 16, 16)) < 0.3).astype(np.uint8))  # one folder, one stem
    out3 = tmp_path / "out3"
    out3.mkdir()
    assert main(["reconstruct", str(tmp_path / "m2" / "x.npy"), str(tmp_path / "m2" / "x.npz"), "--cfa", cfa,
                 "--at", "20", "--out", str(out3)]) == 0
    assert sorted(p.name for p in out3.glob("*.exr")) == ["m2_x_tfp_t20.exr", "m2_x_tfp_t20_2.exr"]
    np.savez(tmp_path / "m1" / "cam.npz", dark=np.zeros((16, 16)))
    (tmp_path / "m1" / "cam.toml").write_text("# a camera profile\n")
    out2 = tmp_path / "out2"
    out2.mkdir()
    assert main(["reconstruct", str(tmp_path / "m1"), "--cfa", cfa, "--at", "20", "--out", str(out2)]) == 0
    assert [p.name for p in out2.glob("*.exr")] == ["x_tfp_t20.exr"]
    capsys.readouterr()
    (tmp_path / "bad1.npy").write_bytes(b"junk")
    (tmp_path / "bad2.npy").write_bytes(b"junk")
    assert main(["reconstruct", str(tmp_path / "bad1.npy"), str(tmp_path / "bad2.npy"), "--out", str(out2)]) == 1
    assert "all 2 inputs failed (said above); nothing was written" in capsys.readouterr().err
