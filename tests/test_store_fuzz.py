"""A corpus of damaged batch stores, presets and sidecars: one sentence each, never "this is a bug", no leftovers.

Every damaged store goes through ``spikeview export`` (and, where it matters, ``--resume``): the store
check (:func:`spikeview.cluster.store.check_store`) refuses it in one sentence naming the store, or
``--resume`` recomputes the damaged chunk and the store then equals the undamaged one. A seeded
hypothesis run mutates random files of a store the same way. Bayer and monochrome stores both.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

pytest.importorskip("distributed")
zarr = pytest.importorskip("zarr")

from spikeview.cli.main import main  # noqa: E402
from spikeview.io.plain import write_plain  # noqa: E402

MISSING = object()
# 10 windows of 4 ticks in chunks of 4: chunks 0, 1 (windows 4-7), 2 (windows 8-9)
RUN = ["--window", "4", "--range", "2:42:4", "--chunk", "4"]


def _write(path: Path, cfa: str) -> list[str]:
    rng = np.random.default_rng(3)
    ramp = np.linspace(0.05, 0.9, 16, dtype=np.float32)[None, None, :]
    write_plain(path, (rng.random((48, 16, 16)) < ramp).astype(np.uint8))
    return [str(path), "--width", "16", "--height", "16", "--cfa", cfa]


@pytest.fixture(scope="module")
def bases(tmp_path_factory):
    """Two finished stores (Bayer, monochrome) and their inputs; each case copies one."""
    d = tmp_path_factory.mktemp("bases")
    out = {}
    for kind, cfa in (("bayer", "RGGB"), ("mono", "none")):
        src = _write(d / f"{kind}.dat", cfa)
        assert main(["reconstruct", *src, *RUN, "--out", str(d / f"{kind}.zarr")]) == 0
        out[kind] = (src, d / f"{kind}.zarr", np.asarray(zarr.open_group(str(d / f"{kind}.zarr"))["frames"][:]))
    return out


def _copy(bases, kind: str, tmp: Path) -> tuple[list[str], Path, np.ndarray]:
    src, store, frames = bases[kind]
    dst = tmp / "s.zarr"
    shutil.copytree(store, dst)
    return src, dst, frames


def _listing(folder: Path) -> list[str]:
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*") if "s.zarr" not in p.parts)


def _one_sentence(capsys, rc: int, needle: str = "s.zarr", what: str = "") -> str:
    err = capsys.readouterr().err.strip()
    lines = [ln for ln in err.splitlines() if ln.startswith("spikeview: error:")]
    assert rc == 1, (what, err)
    assert len(lines) == 1 and err.endswith(lines[0]), (what, err)
    assert "this is a bug" not in err and "Traceback" not in err, (what, err)
    assert needle in lines[0], (what, err)
    return lines[0]


# --------------------------------------------------------------------------- the damages
def _file(rel: str, how: str):
    def damage(store: Path) -> None:
        p = store / rel
        if how == "truncate":
            p.write_bytes(p.read_bytes()[: max(1, p.stat().st_size // 2)])
        elif how == "empty":
            p.write_bytes(b"")
        elif how == "garbage":
            p.write_bytes(np.random.default_rng(5).integers(0, 256, 300, dtype=np.uint8).tobytes())
        elif how == "delete":
            p.unlink() if p.is_file() else shutil.rmtree(p)
        elif how == "flip":  # one bit in the middle: decodes without a checksum, so the store keeps one
            data = bytearray(p.read_bytes())
            data[len(data) // 2] ^= 0x10
            p.write_bytes(bytes(data))
    return damage


def _attr(key: str, value):
    def damage(store: Path) -> None:
        g = zarr.open_group(str(store), mode="r+")
        a = dict(g.attrs["spikeview"])
        if value is MISSING:
            a.pop(key)
        else:
            a[key] = value
        g.attrs["spikeview"] = a
    return damage


def _array(name: str, shape_of, dtype="float32", chunks_of=None):
    def damage(store: Path) -> None:
        g = zarr.open_group(str(store), mode="r+")
        old = g[name]
        shape = shape_of(tuple(old.shape))
        chunks = chunks_of(tuple(old.chunks)) if chunks_of else shape
        del g[name]
        g.create_array(name, shape=shape, chunks=chunks, dtype=dtype, fill_value=0)[...] = 0.5
    return damage


def _done_value(v: int):
    def damage(store: Path) -> None:
        zarr.open_group(str(store), mode="r+")["done"][1] = v
    return damage


#: damages that ``--resume`` repairs (the chunk is recomputed); export names the chunk or the markers
RECOMPUTED = {
    "truncated chunk": (_file("frames/c/1/0/0/0", "truncate"), "chunk 1 (windows 4-7)"),
    "empty chunk": (_file("frames/c/1/0/0/0", "empty"), "chunk 1 (windows 4-7)"),
    "garbage chunk": (_file("frames/c/1/0/0/0", "garbage"), "chunk 1 (windows 4-7)"),
    "deleted chunk": (_file("frames/c/1/0/0/0", "delete"), "chunk 1 (windows 4-7)"),
    "one bit flipped in a chunk": (_file("frames/c/1/0/0/0", "flip"), "chunk 1 (windows 4-7)"),
    "missing done array": (_file("done", "delete"), "completion markers"),
    "garbage done metadata": (_file("done/zarr.json", "garbage"), "completion markers"),
    "garbage done marker": (_file("done/c/1", "garbage"), "completion markers of chunk(s) 1"),
    "empty done marker": (_file("done/c/1", "empty"), "completion markers of chunk(s) 1"),
    "done marker of 7": (_done_value(7), "completion markers of chunk(s) 1"),
}

#: the timings array (not needed by export): --resume rewrites it without recomputing anything
TIMINGS = {"missing seconds array": _file("seconds", "delete"), "garbage seconds metadata": _file("seconds/zarr.json", "garbage")}

#: damages refused by export and by --resume alike (one sentence naming the store)
REFUSED = {
    "missing centre_tick": _file("centre_tick", "delete"),
    "garbage centre_tick metadata": _file("centre_tick/zarr.json", "garbage"),
    "garbage centre_tick chunk": _file("centre_tick/c/0", "garbage"),
    "missing window array": _file("window", "delete"),
    "garbage frames metadata": _file("frames/zarr.json", "garbage"),
    "empty frames metadata": _file("frames/zarr.json", "empty"),
    "garbage group metadata": _file("zarr.json", "garbage"),
    "missing group metadata": _file("zarr.json", "delete"),
    "missing frames": _file("frames", "delete"),
    "frames of rank 3": _array("frames", lambda s: s[:3]),
    "frames of fewer windows": _array("frames", lambda s: (s[0] - 2, *s[1:]), chunks_of=lambda c: c),
    "frames of 4 channels": _array("frames", lambda s: (*s[:3], 4), chunks_of=lambda c: (*c[:3], 4)),
    "frames of float64": _array("frames", lambda s: s, "float64", chunks_of=lambda c: c),
    "frames chunked otherwise": _array("frames", lambda s: s, chunks_of=lambda c: (2, *c[1:])),
    "no spikeview attribute": _attr("format", MISSING),
    "format 2": _attr("format", 2),
}
for key, values in {
    "recipe": [MISSING, 5, "[[[ not toml", "[nonsense]\nx = 1\n"],
    "method": [MISSING, 3, "magic", "guided"],
    "step": [MISSING, "4", 0, -4, 3],
    "chunk": [MISSING, 0, 2.5, 3, True],
    "tick_rate": [MISSING, "fast", 0, -1.0],
    "input": [MISSING, 7, ""],
    "white_point": [MISSING, "bright", 0, 0.0, -1.0, None, [1.0], 1e-300, 1e308],
    "alpha": [MISSING, [1.0, 2.0], "red", [1.0, -1.0, 1.0], [0, 0, 0]],
    "fingerprint": [MISSING, "abc", {}, {"name": 1, "size": 2, "blake2b": "z"}],
    "keyframe": [MISSING, 0, -16, "16"],
    "n_windows": [MISSING, 11, 9, 0],
    "frame_shape": [MISSING, [16, 16, 4], [16, 16], "16x16"],
    "settings": [MISSING, "x", {"run": {"method": "nope"}}, {"bogus": {}}, {"run": {"method": "guided"}}],
    "window": [MISSING, 0, 11],
}.items():
    for v in values:
        REFUSED[f"{key} = {'missing' if v is MISSING else repr(v)}"] = _attr(key, v)


@pytest.mark.parametrize("kind", ["bayer", "mono"])
def test_refused_stores_give_one_sentence_and_leave_nothing(bases, tmp_path, capsys, kind):
    """Every refused damage, through ``export`` (npy, and MP4/PNG for some) and ``--resume``."""
    count = 0
    for i, (name, damage) in enumerate(REFUSED.items()):
        case = tmp_path / f"{i}"
        case.mkdir()
        src, store, _ = _copy(bases, kind, case)
        damage(store)
        before = _listing(case)
        outs = [case / "o.npy"] + ([case / "o.mp4", case / "f_%03d.png"] if i % 8 == 0 else [])
        for out in outs:
            line = _one_sentence(capsys, main(["export", str(store), "--out", str(out)]))
            assert _listing(case) == before, (name, line)
            count += 1
        if i % 3 == 0 or "tick" in name or "input" in name:
            line = _one_sentence(capsys, main(["reconstruct", *src, "--out", str(store), "--resume"]))
            assert _listing(case) == before, (name, line)
            count += 1
    assert count > len(REFUSED)


@pytest.mark.parametrize("kind", ["bayer", "mono"])
def test_damaged_chunks_and_markers_are_named_by_export_and_recomputed_by_resume(bases, tmp_path, capsys, kind):
    for i, (name, (damage, needle)) in enumerate(RECOMPUTED.items()):
        case = tmp_path / f"{i}"
        case.mkdir()
        src, store, frames = _copy(bases, kind, case)
        damage(store)
        before = _listing(case)
        for out in ["o.npy"] + (["o.mp4", "f_%03d.png", "f_%03d.exr"] if i < 4 else []):
            line = _one_sentence(capsys, main(["export", str(store), "--out", str(case / out)]))
            assert needle in line and "--resume" in line, (name, line)
            assert _listing(case) == before, (name, out)  # no partial output, no preset
        assert main(["reconstruct", *src, "--out", str(store), "--resume"]) == 0, name
        assert "recomput" in capsys.readouterr().err, name
        g = zarr.open_group(str(store), mode="r")
        assert np.asarray(g["done"][:]).all(), name
        np.testing.assert_array_equal(np.asarray(g["frames"][:]), frames, err_msg=name)
        assert main(["export", str(store), "--out", str(case / "o.npy")]) == 0, name


@pytest.mark.parametrize("name", sorted(TIMINGS))
def test_lost_timings_do_not_stop_export_and_resume_rewrites_them(bases, tmp_path, capsys, monkeypatch, name):
    import spikeview.pipeline as pipeline

    src, store, frames = _copy(bases, "mono", tmp_path)
    TIMINGS[name](store)
    assert main(["export", str(store), "--out", str(tmp_path / "o.npy")]) == 0
    computed = []
    real = pipeline.reconstruct_windows

    def counting(*a, **k):
        for f in real(*a, **k):
            computed.append(1)
            yield f

    monkeypatch.setattr(pipeline, "reconstruct_windows", counting)
    assert main(["reconstruct", *src, "--out", str(store), "--resume"]) == 0
    assert computed == []  # every chunk was done: nothing recomputed
    g = zarr.open_group(str(store), mode="r")
    assert g["seconds"].shape == (3,) and np.asarray(g["done"][:]).all()


def test_a_file_or_an_empty_folder_named_like_a_store(bases, tmp_path, capsys):
    src = bases["bayer"][0]
    (tmp_path / "s.zarr").write_bytes(b"not a store")
    _one_sentence(capsys, main(["export", str(tmp_path / "s.zarr"), "--out", str(tmp_path / "o.npy")]))
    _one_sentence(capsys, main(["reconstruct", *src, "--out", str(tmp_path / "s.zarr"), "--resume"]))
    (tmp_path / "s.zarr").unlink()
    (tmp_path / "s.zarr").mkdir()
    _one_sentence(capsys, main(["export", str(tmp_path / "s.zarr"), "--out", str(tmp_path / "o.npy")]))
    _one_sentence(capsys, main(["reconstruct", *src, "--out", str(tmp_path / "s.zarr"), "--resume"]))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.zarr"]


@settings(max_examples=25, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(pick=st.integers(0, 10_000), how=st.sampled_from(["truncate", "empty", "garbage", "flip", "delete"]),
       seed=st.integers(0, 2**16))
def test_random_damage_is_refused_or_recomputed(bases, tmp_path_factory, capsys, pick, how, seed):
    """Any file of a store mutated: export succeeds or says one sentence; a resume then finishes it or says one."""
    case = tmp_path_factory.mktemp("h")
    src, store, frames = _copy(bases, "bayer", case)
    files = sorted(p for p in store.rglob("*") if p.is_file())
    target = files[pick % len(files)]
    data = bytearray(target.read_bytes())
    rng = np.random.default_rng(seed)
    if how == "flip" and data:
        data[int(rng.integers(len(data)))] ^= 1 << int(rng.integers(8))
        target.write_bytes(bytes(data))
    elif how == "delete":
        target.unlink()
    else:
        _file(str(target.relative_to(store)), how)(store)
    for argv in (["export", str(store), "--out", str(case / "o.npy")],
                 ["reconstruct", *src, "--out", str(store), "--resume"]):
        rc = main(argv)
        if rc != 0:
            _one_sentence(capsys, rc)
            assert not (case / "o.npy").exists()
        capsys.readouterr()


# ------------------------------------------------------------------------ presets and sidecars
PRESETS = {
    "empty": b"",
    "garbage": bytes(range(256)),
    "not toml": b"[[[ run\n",
    "unknown table": b"[nonsense]\nx = 1\n",
    "wrong type": b"[classical]\nwindow = \"ten\"\n",
    "out of range": b"[export]\nwhite = 0\n",
    "bad method": b"[run]\nmethod = \"magic\"\n",
    "nan fps": b"[export]\nfps = nan\n",
    "inf fps": b"[export]\nfps = inf\n",
    "tiny fps": b"[export]\nfps = 1e-300\n",
    # issue 29: export levels by the rules of their flags (a ZeroDivisionError once; the others were accepted)
    "negative black, zero white": b"[export]\nblack = -0.5\nwhite = 0.0\n",
    "negative white": b"[export]\nwhite = -0.5\n",
    "huge white": b"[export]\nwhite = 1e308\n",
    "negative black": b"[export]\nblack = -0.5\n",
    "black above full scale": b"[export]\nblack = 2.0\n",
}


def test_bad_presets_give_one_sentence_and_leave_nothing(bases, tmp_path, capsys):
    src = bases["bayer"][0]
    (tmp_path / "folder.toml").mkdir()
    cases = {"a folder": tmp_path / "folder.toml", "missing": tmp_path / "nosuch.toml"}
    for name, data in PRESETS.items():
        cases[name] = tmp_path / f"{len(cases)}.toml"
        cases[name].write_bytes(data)
    before = _listing(tmp_path)
    for name, preset in cases.items():
        for out in ("o.npy", "o.mp4", "o.zarr"):
            rc = main(["reconstruct", src[0], "--preset", str(preset), "--range", "2:42:4", "--out",
                       str(tmp_path / out)])
            _one_sentence(capsys, rc, needle="", what=f"{name} -> {out}")
            assert _listing(tmp_path) == before, (name, out)


SIDECARS = {
    "garbage": bytes(range(256)),
    "not toml": b"width = = 3\n",
    "wrong type": b"width = \"wide\"\nheight = 16\n",
    "negative": b"width = -16\nheight = 16\n",
    "too large": b"width = 4096\nheight = 4096\n",
    "bad cfa": b"width = 16\nheight = 16\ncfa = \"XYZW\"\n",
}


def test_bad_sidecars_give_one_sentence_and_leave_nothing(bases, tmp_path, capsys):
    raw = Path(bases["bayer"][0][0]).read_bytes()
    for name, data in SIDECARS.items():
        case = tmp_path / name.replace(" ", "_")
        case.mkdir()
        (case / "c.dat").write_bytes(raw)
        (case / "c.dat.toml").write_bytes(data)
        before = _listing(case)
        for out in ("o.npy", "o.zarr"):
            rc = main(["reconstruct", str(case / "c.dat"), "--range", "2:42:4", "--out", str(case / out)])
            _one_sentence(capsys, rc, needle="c.dat", what=f"{name} -> {out}")
            assert _listing(case) == before, (name, out)


def test_a_preset_whose_stream_describes_another_file(bases, tmp_path, capsys):
    """The input's sidecar wins over a preset's [stream] that disagrees with it (said in a note, with the
    flags that choose otherwise); without a sidecar the preset's table is used and the note names the file
    the preset was written for; geometry flags win over both."""
    src = bases["bayer"][0]
    preset = tmp_path / "other.toml"
    preset.write_text("# spikeview reconstruct preset for /elsewhere/other.dat\n"
                      "[stream]\nformat = \"plain\"\nwidth = 8\nheight = 8\ncfa = \"RGGB\"\n[classical]\nwindow = 4\n")
    assert main(["reconstruct", src[0], "--preset", str(preset), "--at", "20", "--out", str(tmp_path / "a.npy")]) == 0
    err = capsys.readouterr().err
    assert "other.toml's [stream] table describes another file (width = 8, height = 8, cfa = 'RGGB')" in err, err
    assert "read by its sidecar (give --width --height --cfa to choose otherwise)" in err, err
    assert np.load(tmp_path / "a.npy").squeeze(0).shape == (16, 16)  # the sidecar's 16x16 monochrome
    # a flag wins over both
    assert main(["reconstruct", src[0], "--preset", str(preset), "--at", "20", "--cfa", "RGGB",
                 "--out", str(tmp_path / "b.npy")]) == 0
    err = capsys.readouterr().err
    assert "(width = 8, height = 8)" in err and np.load(tmp_path / "b.npy").squeeze(0).shape == (16, 16, 3)
    # no sidecar: the preset's table reads the file, and the note says whose table it is
    bare = tmp_path / "bare.dat"
    bare.write_bytes(Path(src[0]).read_bytes())
    assert main(["reconstruct", str(bare), "--preset", str(preset), "--at", "20", "--out", str(tmp_path / "c.npy")]) == 0
    err = capsys.readouterr().err
    assert "other.toml was written for other.dat" in err and "bare.dat, which has no sidecar" in err, err
    assert np.load(tmp_path / "c.npy").squeeze(0).shape == (8, 8, 3)
    # the file's own preset (its header names this file) re-runs as recorded, sidecar or not
    own = tmp_path / "own.toml"
    own.write_text(preset.read_text().replace("/elsewhere/other.dat", f"/somewhere/{Path(src[0]).name}"))
    assert main(["reconstruct", src[0], "--preset", str(own), "--at", "20", "--out", str(tmp_path / "d.npy")]) == 0
    assert "[stream]" not in capsys.readouterr().err
    assert np.load(tmp_path / "d.npy").squeeze(0).shape == (8, 8, 3)
