"""``spikeview reconstruct`` without ``--out`` (the command of issue 15): a named default in the
current folder, never replacing a file unless ``--overwrite`` is given. Monochrome and Bayer."""

from __future__ import annotations

import numpy as np
import pytest

from spikeview.cli.main import main


@pytest.mark.parametrize("cfa", ["none", "RGGB"])
def test_reconstruct_without_out_writes_a_fresh_default_name_each_run(tmp_path, monkeypatch, capsys, cfa):
    src = tmp_path / "in" / "cap.npy"
    src.parent.mkdir()
    np.save(src, (np.random.default_rng(1).random((60, 16, 16)) < 0.3).astype(np.uint8))
    monkeypatch.chdir(tmp_path)
    argv = ["reconstruct", str(src), "--cfa", cfa, "--at", "30"]
    assert main(argv) == 0
    first = (tmp_path / "cap_tfp_t30.exr").read_bytes()
    assert (tmp_path / "cap_tfp_t30.exr.preset.toml").exists()
    assert main(argv) == 0  # the same command again: a new name, the first file kept byte for byte
    err = capsys.readouterr().err
    assert "writing cap_tfp_t30_2.exr" in err, err
    assert (tmp_path / "cap_tfp_t30.exr").read_bytes() == first
    assert (tmp_path / "cap_tfp_t30_2.exr").exists() and (tmp_path / "cap_tfp_t30_2.exr.preset.toml").exists()
    assert main(argv + ["--overwrite"]) == 0  # --overwrite: the plain name is replaced, no _3
    assert not (tmp_path / "cap_tfp_t30_3.exr").exists()
    assert main(["reconstruct", str(src), "--cfa", cfa, "--range", "10:50:10"]) == 0
    assert (tmp_path / "cap_tfp_10-50.mp4").stat().st_size > 0
    assert sorted(p.name for p in (tmp_path / "in").iterdir()) == ["cap.npy"]  # nothing beside the input


def test_preset_only_in_the_way_also_moves_to_the_next_name(tmp_path, monkeypatch):
    src = tmp_path / "cap.npy"
    np.save(src, (np.random.default_rng(2).random((40, 8, 8)) < 0.3).astype(np.uint8))
    monkeypatch.chdir(tmp_path)
    (tmp_path / "cap_tfp_t20.exr.preset.toml").write_text("# mine\n")
    assert main(["reconstruct", str(src), "--cfa", "none", "--at", "20"]) == 0
    assert (tmp_path / "cap_tfp_t20.exr.preset.toml").read_text() == "# mine\n"
    assert (tmp_path / "cap_tfp_t20_2.exr").exists()
