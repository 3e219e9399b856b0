"""dmtrack.calibration: the self-calibrating bundle adjustment of corner tracks — its Jacobians against finite
differences, the Schur step against a dense solve, the focal length (and k1) recovered where the optimum is known, and
``calibrate-from-video``'s tracks method on a rendered sequence and on Tsukuba."""

from __future__ import annotations

import json

import numpy as np
import pytest

from dmtrack.calibration import Observations, self_calibrate, triangulate
from dmtrack.calibration.bundle import _Problem, inverse_blocks, residuals_and_jacobians
from dmtrack.geometry.lie import so3_exp


def _scene(seed: int = 0, f: float = 500.0, k1: float = 0.0, noise: float = 0.0, n_cams: int = 12, n_pts: int = 300):
    """Cameras on an arc that turn ±20° about y and ±8° about x, looking at points 3–6 m away; exact projections
    (plus ``noise`` px) of the points each camera sees inside its 640 × 480 image."""
    rng = np.random.default_rng(seed)
    X = np.c_[rng.uniform(-3, 3, n_pts), rng.uniform(-2, 2, n_pts), rng.uniform(3, 6, n_pts)]
    s = np.linspace(-1, 1, n_cams)
    R = so3_exp(np.c_[np.radians(8) * np.sin(2.1 * s), np.radians(20) * s, np.radians(3) * np.cos(1.3 * s)])
    C = np.c_[0.6 * s, 0.1 * np.sin(3 * s), 0.3 * s * s]  # camera centres
    t = -np.einsum("nij,nj->ni", R, C)
    cam, pt, uv = [], [], []
    for i in range(n_cams):
        Xc = X @ R[i].T + t[i]
        x, y = Xc[:, 0] / Xc[:, 2], Xc[:, 1] / Xc[:, 2]
        d = 1 + k1 * (x * x + y * y)
        u, v = f * d * x + 319.5, f * d * y + 239.5
        ok = (Xc[:, 2] > 0) & (u >= 0) & (u < 640) & (v >= 0) & (v < 480)
        cam.append(np.full(ok.sum(), i))
        pt.append(np.flatnonzero(ok))
        uv.append(np.c_[u[ok], v[ok]] + rng.normal(0, noise, (ok.sum(), 2)))
    obs = Observations(np.concatenate(pt), np.concatenate(cam), np.concatenate(uv))
    return R, t, X, obs


def test_jacobians_match_finite_differences():
    R, t, X, obs = _scene(k1=-0.05)
    f, k1 = 480.0, -0.03
    res, Jp, Jx, Ji, _ = residuals_and_jacobians(R, t, X, f, k1, 319.5, 239.5, obs, True)
    eps = 1e-6
    o = 17  # an observation
    i, p = obs.camera[o], obs.point[o]
    for k in range(6):
        d = np.zeros(6)
        d[k] = eps
        R2, t2 = R.copy(), t.copy()
        dR = so3_exp(d[:3])
        R2[i], t2[i] = dR @ R[i], dR @ t[i] + d[3:]
        num = (residuals_and_jacobians(R2, t2, X, f, k1, 319.5, 239.5, obs, True)[0][o] - res[o]) / eps
        assert np.allclose(num, Jp[o, :, k], rtol=1e-4, atol=1e-3)
    for k in range(3):
        X2 = X.copy()
        X2[p, k] += eps
        num = (residuals_and_jacobians(R, t, X2, f, k1, 319.5, 239.5, obs, True)[0][o] - res[o]) / eps
        assert np.allclose(num, Jx[o, :, k], rtol=1e-4, atol=1e-3)
    num_f = (residuals_and_jacobians(R, t, X, f + eps, k1, 319.5, 239.5, obs, True)[0][o] - res[o]) / eps
    num_k = (residuals_and_jacobians(R, t, X, f, k1 + eps, 319.5, 239.5, obs, True)[0][o] - res[o]) / eps
    assert np.allclose(num_f, Ji[o, :, 0], rtol=1e-5, atol=1e-6) and np.allclose(num_k, Ji[o, :, 1], rtol=1e-5)


def test_the_schur_step_equals_the_dense_solve():
    """The reduced system's step, back-substituted, is the step of the whole damped system solved densely."""
    R, t, X, obs = _scene(n_cams=5, n_pts=40, noise=0.5)
    pr = _Problem(R, t, X + 0.01, 510.0, 0.0, 319.5, 239.5, obs, False)
    lam = 1e-3
    S, s, idx, B, Ci, c = pr.normal_equations(lam)
    keep = pr.free()
    dg = np.zeros(pr.G)
    dg[keep] = -np.linalg.solve(S[np.ix_(keep, keep)], s[keep])
    Bd = np.zeros((len(X), 3))
    np.add.at(Bd, obs.point, np.einsum("nij,ni->nj", B, dg[idx]))
    dx = -np.einsum("nij,nj->ni", Ci, c + Bd)
    # dense: unknowns = free globals, then every point's 3; Huber weights all 1 at these residuals
    e = np.linalg.norm(pr.res, axis=1)
    w = np.where(e <= 1.0, 1.0, 1.0 / e)
    n, G, P = len(obs), pr.G, 3 * len(X)
    J = np.zeros((2 * n, G + P))
    Jg = np.concatenate([pr.Ji, pr.Jp], axis=2)
    for o in range(n):
        J[2 * o:2 * o + 2, idx[o]] += Jg[o] * np.sqrt(w[o])
        J[2 * o:2 * o + 2, G + 3 * obs.point[o]:G + 3 * obs.point[o] + 3] = pr.Jx[o] * np.sqrt(w[o])
    r = (pr.res * np.sqrt(w)[:, None]).ravel()
    H = J.T @ J
    H[np.diag_indices(G + P)] += lam * np.diag(H)
    H[np.diag_indices(G + P)] += np.r_[np.zeros(G), np.full(P, 1e-12)]
    g = J.T @ r
    cols = np.r_[keep, np.arange(G, G + P)]
    full = -np.linalg.solve(H[np.ix_(cols, cols)], g[cols])
    assert np.allclose(full[: len(keep)], dg[keep], rtol=1e-6, atol=1e-9)
    assert np.allclose(full[len(keep):], dx.ravel(), rtol=1e-6, atol=1e-9)


def test_triangulation_is_exact_without_noise():
    R, t, X, obs = _scene()
    seen = np.bincount(obs.point, minlength=len(X)) >= 2
    assert seen.sum() > 250
    assert np.allclose(triangulate(R, t, 500.0, 319.5, 239.5, obs, len(X))[seen], X[seen], atol=1e-7)


@pytest.mark.parametrize("start", [450.0, 550.0])
def test_a_focal_length_10_percent_off_comes_back(start):
    """From 10 % off either way, with 0.3 px of noise: within 0.2 % of the truth; the same from both ends."""
    R, t, X, obs = _scene(noise=0.3)
    res = self_calibrate(R, t, obs, start, 319.5, 239.5)
    assert abs(res.f / 500.0 - 1) < 0.002
    assert res.converged and 0 < res.sigma_f < 2.0 and res.sigma_k1 is None and res.k1 == 0.0
    assert res.median_error_px < 0.5


def test_focal_length_and_k1_together():
    R, t, X, obs = _scene(k1=-0.06, noise=0.2)
    res = self_calibrate(R, t, obs, 450.0, 319.5, 239.5, model="f-k1")
    assert abs(res.f / 500.0 - 1) < 0.003 and abs(res.k1 + 0.06) < 0.005 and res.sigma_k1 > 0
    pinhole = self_calibrate(R, t, obs, 450.0, 319.5, 239.5)  # the wrong model: a worse fit and a wrong f
    assert pinhole.median_error_px > 1.3 * res.median_error_px and abs(pinhole.f / 500.0 - 1) > 0.03


def test_known_poses_stay_and_give_the_focal_length():
    """``fixed_poses``: the true poses held (the ground truth's role), only points and f move: f from 10 % off comes
    back within 0.2 %, and the poses are returned untouched."""
    R, t, X, obs = _scene(noise=0.3)
    res = self_calibrate(R, t, obs, 550.0, 319.5, 239.5, fixed_poses=True)
    assert res.converged and abs(res.f / 500.0 - 1) < 0.002 and res.median_error_px < 0.5
    seen, _ = obs.subset(np.bincount(obs.point)[obs.point] >= 3)
    n = int(seen.point.max()) + 1
    problem = _Problem(R, t, triangulate(R, t, 550.0, 319.5, 239.5, seen, n), 550.0, 0.0, 319.5, 239.5, seen,
                       False, fixed_poses=True)  # fmt: skip
    assert problem.solve() and abs(problem.f / 500.0 - 1) < 0.002
    assert np.array_equal(problem.R, R) and np.array_equal(problem.t, t)


def test_bad_tracks_are_dropped():
    """Corners that slide (an occluding edge's crossing) are outliers of their own track: with a fifth of the tracks
    sliding by up to 3 px, the focal length still comes back within 0.3 %."""
    R, t, X, obs = _scene(noise=0.2, n_pts=400)
    rng = np.random.default_rng(1)
    slide = np.isin(obs.point, rng.choice(400, 80, replace=False))
    uv = obs.uv.copy()
    uv[slide] += (obs.camera[slide] / 11.0)[:, None] * rng.uniform(-3, 3, (1, 2))
    res = self_calibrate(R, t, Observations(obs.point, obs.camera, uv), 550.0, 319.5, 239.5)
    assert abs(res.f / 500.0 - 1) < 0.003
    assert res.points < 400 and len(res.passes) >= 2


def test_nothing_to_adjust_is_a_clear_error():
    R, t, X, obs = _scene(n_cams=2)
    with pytest.raises(ValueError, match="seen in 3 keyframes"):
        self_calibrate(R, t, obs, 500.0, 319.5, 239.5)
    with pytest.raises(ValueError, match="model must be one of"):
        self_calibrate(R, t, obs, 500.0, 319.5, 239.5, model="fxfy")


SYN = "synthetic:n_frames=150,width=320,height=240,seed=1"


def test_affine_refinement_finds_a_warped_patch():
    """A textured image warped by a known affine map (a 12 % zoom, a 4° turn, a shear) with a brightness gain and
    offset: from a start 0.8 px off and an identity warp, the patch centres come back within 0.05 px."""
    import cv2

    from dmtrack.calibration.tracks import refine_affine

    rng = np.random.default_rng(5)
    anchor = cv2.GaussianBlur(rng.uniform(0, 255, (200, 200)).astype(np.float32), (0, 0), 2.0)
    c, th = 1.12, np.radians(4)
    M = c * np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]]) + [[0, 0.03], [0, 0]]
    shift = np.array([7.3, -4.6])
    A = np.c_[M, shift]  # image(x) = 1.1 · anchor(M⁻¹ (x − shift)) + 5
    image = 1.1 * cv2.warpAffine(anchor, A, (200, 200), flags=cv2.INTER_CUBIC) + 5.0
    p0 = np.array([[60.0, 70.0], [100.5, 90.25], [130.0, 140.0]])
    truth = p0 @ M.T + shift
    start = truth + [[0.8, 0.0], [0.0, -0.8], [0.5, 0.5]]
    p, W, ok = refine_affine(anchor, image, p0, start, np.tile(np.eye(2), (3, 1, 1)))
    assert ok.all() and np.abs(p - truth).max() < 0.05 and np.abs(W - M).max() < 0.01


def test_calibrate_from_video_recovers_a_rendered_focal_length(tmp_path, capsys):
    """The tracks method on the odometry's poses: a rendered sequence (true f = 262.5) from 10 % long and 10 % short
    ends within 0.3 % of the truth (0.02 % measured), at the same value from both; the file it writes is what run
    reads."""
    from dmtrack.cli import main
    from dmtrack.datasets.intrinsics import read_intrinsics_file

    results = []
    for start in (288.75, 236.25):
        out = tmp_path / f"cam{start}.txt"
        rc = main(["calibrate-from-video", SYN, "--intrinsics", f"{start},{start},159.5,119.5", "--out", str(out),
                   "--json", "--quiet"])  # fmt: skip
        res = json.loads(capsys.readouterr().out)
        assert rc == 0 and res["method"] == "tracks" and res["converged"]
        assert abs(res["fx"] / 262.5 - 1) < 0.003 and res["fx"] == res["fy"] and res["cx"] == 159.5
        assert read_intrinsics_file(out, 320, 240).fx == pytest.approx(res["fx"], abs=1e-3)
        results.append(res["fx"])
    assert results[0] == pytest.approx(results[1], rel=1e-3)


def test_calibrate_from_video_with_k1_writes_a_radtan_file_that_run_reads(tmp_path, capsys):
    from dmtrack.cli import main

    out = tmp_path / "cam.txt"
    syn = "synthetic:n_frames=60,width=320,height=240,seed=1"
    assert main(["calibrate-from-video", syn, "--model", "f-k1", "--out", str(out), "--quiet"]) == 0
    lines = out.read_text().splitlines()
    assert lines[0].startswith("RadTan ") and len(lines[0].split()) == 9
    assert lines[1] == lines[3] == "320 240" and len(lines[2].split()) == 5  # the output camera, written out
    assert "k1=" in capsys.readouterr().out
    assert main(["run", syn, "--intrinsics", str(out), "--max-frames", "20", "--out", str(tmp_path / "run"),
                 "--no-progress", "--no-pointcloud", "--no-depth-images"]) == 0  # fmt: skip


def test_the_radtan_file_spells_out_its_output_camera(tmp_path):
    """Line 3 of the f-k1 file is the camera dmtrack's ``crop`` gives, written out: DSO's own ``crop`` folds the image
    of a k1 < 0 lens (it chose fx ≈ 63 for 7-Scenes' file, tools/dso_oracle); read back, the same camera as ``crop``."""
    from dmtrack.datasets.undistort import read_calibration_file
    from dmtrack.pipeline.self_calibration import SelfCalibration, write_intrinsics

    calib = SelfCalibration(517.66723456, 517.66723456, 320.0, 240.0, {}, True, 640, 480, k1=-0.0359081234,
                            method="tracks", model="f-k1")  # fmt: skip
    lines = write_intrinsics(calib, tmp_path / "cam.txt", "test").read_text().splitlines()
    assert lines[2] != "crop" and len(lines[2].split()) == 5
    model = read_calibration_file(tmp_path / "cam.txt").model  # the estimate, read back exactly
    assert (model.fx, model.fy, model.cx, model.cy, model.k1, model.k2, model.p1, model.p2) == (
        calib.fx, calib.fy, calib.cx, calib.cy, calib.k1, 0.0, 0.0, 0.0)
    given = read_calibration_file(tmp_path / "cam.txt").undistorter()
    (tmp_path / "crop.txt").write_text("\n".join([lines[0], lines[1], "crop", lines[3]]) + "\n")
    crop = read_calibration_file(tmp_path / "crop.txt").undistorter()
    assert given.mode == "given" and crop.mode == "crop" and given.camera.fx == pytest.approx(510.46, abs=0.01)
    for a, b in ((given.camera.fx, crop.camera.fx), (given.camera.fy, crop.camera.fy),
                 (given.camera.cx, crop.camera.cx), (given.camera.cy, crop.camera.cy)):  # fmt: skip
        assert a == pytest.approx(b, abs=1e-4)


def test_an_estimate_that_is_not_a_camera_writes_no_file(tmp_path):
    from dmtrack.errors import InputError
    from dmtrack.pipeline.self_calibration import SelfCalibration, write_intrinsics

    calib = SelfCalibration(500.0, 500.0, 320.0, 240.0, {}, False, 640, 480, k1=float("nan"), method="tracks",
                            model="f-k1")  # fmt: skip
    with pytest.raises(InputError, match="k1 must be finite"):
        write_intrinsics(calib, tmp_path / "cam.txt", "test")
    assert not (tmp_path / "cam.txt").exists()


def test_the_window_method_takes_no_k1(tmp_path, capsys):
    from dmtrack.cli import main

    assert main(["calibrate-from-video", SYN, "--method", "window", "--model", "f-k1", "--out",
                 str(tmp_path / "c")]) != 0  # fmt: skip
    assert "only the tracks and groundtruth methods estimate k1" in capsys.readouterr().err
    assert main(["calibrate-from-video", SYN, "--model", "f-c", "--out", str(tmp_path / "c")]) != 0
    assert "the tracks method estimates f or f-k1" in capsys.readouterr().err
    assert not (tmp_path / "c").exists()


def test_the_groundtruth_method_recovers_a_rendered_focal_length(tmp_path, capsys):
    """``--method groundtruth``: the rendered sequence's own poses fixed, 10 % long → within 0.3 % of 262.5; a
    sequence without ground truth is a clear error."""
    from dmtrack.cli import main

    out = tmp_path / "cam.txt"
    rc = main(["calibrate-from-video", SYN, "--method", "groundtruth", "--intrinsics", "288.75,288.75,159.5,119.5",
               "--out", str(out), "--json", "--quiet"])  # fmt: skip
    res = json.loads(capsys.readouterr().out)
    assert rc == 0 and res["method"] == "groundtruth" and res["converged"] and abs(res["fx"] / 262.5 - 1) < 0.003
    assert "ground-truth poses" in out.read_text()
    folder = tmp_path / "frames"
    folder.mkdir()
    import cv2

    from dmtrack.datasets import open_sequence

    seq = open_sequence(SYN)
    for i in range(6):
        cv2.imwrite(str(folder / f"{i:04d}.png"), seq[i].image)
    rc = main(["calibrate-from-video", str(folder), "--method", "groundtruth", "--out", str(tmp_path / "c2.txt")])
    assert rc != 0 and "no ground-truth poses" in capsys.readouterr().err


def test_the_groundtruth_method_associates_poses_timed_apart_from_the_frames():
    """Ground truth on its own clock (TUM RGB-D's): each frame takes the pose nearest in time within 10 ms."""
    from dmtrack.datasets import open_sequence
    from dmtrack.io.trajectory import Trajectory
    from dmtrack.pipeline.self_calibration import _calibrate_groundtruth

    seq = open_sequence(SYN)

    class Shifted:  # the rendered sequence with its poses stamped 4 ms late
        timestamps = seq.timestamps
        groundtruth = Trajectory(seq.groundtruth.timestamps + 0.004, seq.groundtruth.poses)

        def __len__(self) -> int:
            return len(seq)

        def __getitem__(self, i: int):  # noqa: ANN204
            return seq[i]

    res = _calibrate_groundtruth(Shifted(), "shifted", [288.75, 288.75, 159.5, 119.5], (320, 240), "f", 5, 0, None,
                                 None)  # fmt: skip
    assert res.converged and abs(res.fx / 262.5 - 1) < 0.003


@pytest.mark.shared
def test_tsukuba_images_and_their_ground_truth_agree_on_622_px(shared_dir):
    """Tsukuba's own poses and its images' corner tracks agree on f ≈ 622 px (the documented 615 fits them worse:
    0.35 against 0.17 px median error over 150 frames); the self-calibration from the images alone (623.7, started at
    676.5) is within 1 % of that — where it is 1.4 % from the documented value."""
    from dmtrack.pipeline.self_calibration import calibrate_from_video

    gt = calibrate_from_video(str(shared_dir / "data" / "tsukuba-150"), intrinsics="676.5,676.5,320,240",
                              method="groundtruth")  # fmt: skip
    assert gt.converged and 619.0 < gt.fx < 626.0 and abs(gt.fx / 615.0 - 1) > 0.005
    images = calibrate_from_video(str(shared_dir / "data" / "tsukuba-150"), intrinsics="676.5,676.5,320,240")
    assert images.converged and abs(images.fx / gt.fx - 1) < 0.01 and abs(images.fx / 615.0 - 1) < 0.02


def test_tracks_follow_corners_in_grey_rgb_rgba_and_float_images():
    """The same corners and positions whatever the image type; each track's camera indices increase by one."""
    from dmtrack.calibration import track_keyframes
    from dmtrack.datasets.synthetic import SyntheticConfig, SyntheticSequence

    seq = SyntheticSequence(SyntheticConfig(n_frames=12, width=160, height=120, seed=2, colour=True))
    rgb = [np.asarray(seq[k].image) for k in range(0, 12, 3)]
    import cv2

    grey = [cv2.cvtColor(im, cv2.COLOR_RGB2GRAY) for im in rgb]
    rgba = [np.dstack([im, np.full(im.shape[:2], 255, np.uint8)]) for im in rgb]
    a, b, c = track_keyframes(grey), track_keyframes(rgb), track_keyframes(rgba)
    assert len(a) > 100 and np.array_equal(a.uv, b.uv) and np.array_equal(a.uv, c.uv)
    d = track_keyframes([g.astype(np.float32) / 255.0 for g in grey])
    assert len(d) > 100 and set(np.unique(d.camera)) == {0, 1, 2, 3}
    for p in np.unique(a.point)[:20]:
        cams = a.camera[a.point == p]
        assert np.array_equal(cams, np.arange(cams[0], cams[0] + len(cams)))


def test_a_calibration_file_is_used_as_it_is(tmp_path):
    """Started from a DSO-format file (which ``--intrinsics`` reads), the odometry and the tracks see the same images
    with the same camera: the rendered focal length comes back."""
    from dmtrack.pipeline.self_calibration import calibrate_from_video

    calib = tmp_path / "camera.txt"
    calib.write_text("RadTan 280 280 159.5 119.5 0 0 0 0\n320 240\nnone\n320 240\n")
    res = calibrate_from_video("synthetic:n_frames=60,width=320,height=240,seed=1", intrinsics=str(calib))
    assert res.method == "tracks" and abs(res.fx / 262.5 - 1) < 0.005


def test_point_blocks_inverted_even_where_one_is_singular() -> None:
    """A point almost in a camera's plane has a huge block of rank 2 (7-Scenes 175+160: ~10²⁶, singular to LAPACK once
    the 10⁻¹² on its diagonal is lost), which stopped calibrate-from-video at its σ. Its block gets the pseudo-inverse;
    every other block is inverted as before, bit for bit."""
    rng = np.random.default_rng(0)
    A = rng.normal(size=(5, 3, 3))
    regular = A @ np.swapaxes(A, 1, 2) + 0.1 * np.eye(3)
    assert np.array_equal(inverse_blocks(regular), np.linalg.inv(regular))
    a = 2.0**86  # ~8·10²⁵, a power of two: the elimination leaves an exact zero pivot
    singular = np.array([[a, a, 0.0], [a, a, 0.0], [0.0, 0.0, a]]) + 1e-12 * np.eye(3)
    with pytest.raises(np.linalg.LinAlgError):
        np.linalg.inv(singular)
    stack = np.concatenate([regular[:2], singular[None], regular[2:]])
    out = inverse_blocks(stack)
    assert np.isfinite(out).all()
    assert np.array_equal(out[[0, 1, 3, 4, 5]], np.stack([np.linalg.inv(b) for b in regular]))
    assert np.allclose(out[2], np.linalg.pinv(singular, hermitian=True), rtol=0, atol=1e-40)
