"""spikeview.io.views: a locked source reads what its source reads; a view flips and renames without copying the file."""

import threading

import numpy as np

from spikeview.io import ArraySource
from spikeview.io.views import LockedSource, ViewSource


def _spikes():
    return (np.random.default_rng(4).random((12, 6, 8)) < 0.4).astype(np.uint8)


def test_locked_source_reads_and_counts_like_its_source_from_many_threads():
    src = ArraySource(_spikes(), cfa="RGGB")
    locked = LockedSource(src)
    assert locked.info is src.info and locked.cfa == "RGGB"
    out = []
    threads = [threading.Thread(target=lambda a=a: out.append((a, locked.count(a, a + 4)))) for a in range(8)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert len(out) == 8 and all(np.array_equal(c, src.count(a, a + 4)) for a, c in out)


def test_view_source_flips_reads_and_counts_and_names_the_cfa():
    spikes = _spikes()
    src = ArraySource(spikes, cfa="RGGB")
    view = ViewSource(src, "GBRG", flip_vertical=True)
    assert view.cfa == "GBRG" and view.info.flip_vertical
    np.testing.assert_array_equal(view.read(2, 5), spikes[2:5, ::-1])
    np.testing.assert_array_equal(view.count(0, 12), spikes.sum(axis=0)[::-1])
    same = ViewSource(src, None, flip_vertical=False)  # monochrome reading, not flipped
    assert same.cfa is None and np.array_equal(same.read(0, 3), spikes[:3])
