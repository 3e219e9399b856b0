"""``--frames`` (dmtrack.datasets.selection): a selection of a sequence's frames as a sequence of its own."""

from __future__ import annotations

import numpy as np
import pytest

from dmtrack.datasets import open_sequence
from dmtrack.datasets.selection import FrameSelection, parse_frames, select_frames
from dmtrack.errors import InputError


def test_parse_frames() -> None:
    assert parse_frames("0-3,10:12,20", 30).tolist() == [0, 1, 2, 3, 10, 11, 20]
    assert parse_frames(" 5 - 6 , 8 ", 10).tolist() == [5, 6, 8]
    for bad, why in (("3-1", "empty"), ("0-40", "outside"), ("5,3", "increase"), ("0-3,3", "increase"),
                     ("a-b", "not N"), ("", "not N"), ("1-2-3", "not N")):  # fmt: skip
        with pytest.raises(InputError, match=why):
            parse_frames(bad, 30)


def test_a_selection_is_the_original_frames_renumbered() -> None:
    seq = open_sequence("synthetic:n_frames=30,width=64,height=48,seed=1")
    sel = select_frames(seq, "0-4,20-24")
    assert isinstance(sel, FrameSelection) and len(sel) == 10 and sel.name.endswith("[0-4,20-24]")
    assert np.array_equal(sel.timestamps, seq.timestamps[[0, 1, 2, 3, 4, 20, 21, 22, 23, 24]])
    f = sel[5]
    assert f.index == 5 and f.timestamp == seq[20].timestamp
    assert np.array_equal(f.image, seq[20].image) and np.array_equal(f.pose, seq[20].pose)
    assert sel.read_frame(6, depth=False).index == 6 and sel.camera == seq.camera
    assert sel.groundtruth is not None and len(sel.groundtruth) == len(seq)  # runs associate by timestamp
    assert select_frames(seq, None) is seq
    with pytest.raises(IndexError):
        sel[10]


def test_a_run_on_a_selection() -> None:
    import dmtrack

    r = dmtrack.track("synthetic:n_frames=40,width=160,height=120,seed=1", frames="0-19,25-29", init="random")
    assert r.metrics["total_frames"] == 25 and r.metrics["sequence"].endswith("[0-19,25-29]")
    with pytest.raises(InputError, match="outside"):
        dmtrack.track("synthetic:n_frames=40,width=160,height=120,seed=1", frames="0-50")
