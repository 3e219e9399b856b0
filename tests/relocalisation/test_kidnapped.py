"""A kidnapped camera (issue 37): the run jumps, between two frames, to a place the map saw earlier.

Synthetic room, seed 4: frames 0–149 and then 270–329 of its trajectory, so that between the run's frames 149 and 150
the camera jumps 0.65 m and turns 37° (frame 270 is 0.12 m and 9° from frame 8). With ``stop_on_loss`` off the
odometry must notice the jump at once, give the frames no pose until it has found the camera again on a keyframe of
the run (the relocaliser), and go on in the same map; a run that did not notice (the jump test off) tracks on with
wrong poses.
"""

from __future__ import annotations

import numpy as np
import pytest

import dmtrack
from dmtrack.io.association import associate_trajectories
from dmtrack.odometry.config import VOConfig

SEQ = "synthetic:n_frames=330,width=320,height=240,seed=4"
FRAMES = "0-149,270-329"
JUMP = 150  # the run's first frame after the jump


@pytest.fixture(scope="module")
def kidnapped() -> dmtrack.pipeline.RunResult:
    return dmtrack.track(SEQ, "gray", VOConfig(stop_on_loss=False), frames=FRAMES)


def test_the_jump_is_noticed_and_the_camera_found_again_within_a_few_frames(kidnapped) -> None:  # noqa: ANN001
    m = kidnapped.metrics
    assert m["lost_at"] in (JUMP, JUMP + 1)  # within a frame of the jump
    assert m["relocalisations"] >= 1
    found = m["relocalised"][0]
    assert found["lost_since"] == m["lost_at"] and found["frame"] - JUMP <= 10
    assert m["tracked_frames"] >= 0.95 * m["total_frames"]
    assert m["lost_spans"][0][0] == m["lost_at"] and m["lost_frames"] == found["frame"] - found["lost_since"]
    assert len(m["segments"]) == 1  # the same map: no new segment


def test_no_frame_gets_a_wrong_pose(kidnapped) -> None:  # noqa: ANN001
    """Every posed frame — before the jump and after it — lies where the ground truth says, after one Sim(3)
    alignment of the whole run; the lost frames have no pose at all."""
    m = kidnapped.metrics
    assert m["ate_rmse"] < 0.02
    gt, est = associate_trajectories(kidnapped.groundtruth, kidnapped.trajectory, max_diff=1e-6)
    from dmtrack.evaluation.metrics import ate

    a = ate(gt, est, "sim3")
    assert float(np.max(a.errors)) < 0.06  # not one frame off by much (the jump is 0.65 m)
    lost = {f for s, e in m["lost_spans"] for f in range(s, e + 1)}
    assert not lost & set(kidnapped.frame_indices.tolist())


def test_without_the_jump_test_the_kidnapped_run_goes_wrong(kidnapped) -> None:  # noqa: ANN001
    """The residual-jump test is what catches this jump: without it LSD-SLAM's own test passes the frame (more than
    half of its points "good") and the run tracks on from a wrong pose."""
    blind = dmtrack.track(SEQ, "gray", VOConfig(stop_on_loss=False).with_overrides("keyframe.loss_residual_jump=null"),
                          frames=FRAMES)  # fmt: skip
    assert blind.metrics["lost_frames"] == 0 and blind.metrics["relocalisations"] == 0
    assert blind.metrics["ate_rmse"] > 5 * kidnapped.metrics["ate_rmse"]


def test_a_run_that_stops_at_a_loss_stops_at_the_jump() -> None:
    r = dmtrack.track(SEQ, "gray", frames=FRAMES)
    assert r.metrics["lost_at"] == JUMP and r.metrics["tracked_frames"] == JUMP


def test_bitplanes_notices_the_jump_by_its_residual_alone() -> None:
    """Bit-Planes' residuals stay below the "good" threshold, so its good ratio is always 1 and cannot show the jump;
    its residual alone does (``keyframe.loss_residual_jump_without_bad``), and the camera is found again with the
    same care (a frame with no bad point is found only at a residual like the tracked frames'). Without that test
    the run tracks on from a wrong pose."""
    config = VOConfig(stop_on_loss=False)
    r = dmtrack.track(SEQ, "bitplanes", config, frames=FRAMES)
    m = r.metrics
    assert m["lost_at"] in (JUMP, JUMP + 1) and m["relocalisations"] >= 1
    assert m["relocalised"][0]["frame"] - JUMP <= 10 and m["tracked_frames"] >= 0.95 * m["total_frames"]
    assert m["ate_rmse"] < 0.02
    blind = dmtrack.track(SEQ, "bitplanes", config.with_overrides("keyframe.loss_residual_jump_without_bad=null"),
                          frames=FRAMES)  # fmt: skip
    assert blind.metrics["lost_frames"] == 0 and blind.metrics["ate_rmse"] > 5 * m["ate_rmse"]
