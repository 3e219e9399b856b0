"""ICL-NUIM reader (TUM-compatible release) and its pose convention (negative fy of the release)."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from dmtrack.cli import main
from dmtrack.datasets import detect_format, open_sequence
from dmtrack.datasets.iclnuim import CAMERA, mirror_poses
from dmtrack.errors import InputError

W, H = 640, 480
FX, FY_RELEASE, CX, CY = 481.20, -480.0, 319.5, 239.5  # the official calibration, fy negative


def _scene(rng: np.random.Generator) -> np.ndarray:
    """A grid of points at random depths (a grid keeps the dots apart)."""
    g = np.stack(np.meshgrid(np.linspace(-0.45, 0.45, 8), np.linspace(-0.32, 0.32, 5)), -1).reshape(-1, 2)
    z = rng.uniform(2.5, 4.0, len(g))
    return np.column_stack([g * z[:, None], z])


def _release_poses(n: int) -> np.ndarray:
    """Camera-to-world poses as the release stores them (first pose at z = −2.25 like livingRoom0)."""
    T = np.tile(np.eye(4), (n, 1, 1))
    T[:, :3, :3] = Rotation.from_rotvec(np.linspace(0, 0.15, n)[:, None] * np.array([0.2, 1.0, 0.3])).as_matrix()
    T[:, :3, 3] = np.array([0.0, 0.0, -2.25]) + np.linspace(0, 0.3, n)[:, None] * np.array([1.0, 0.4, 0.2])
    return T


def _project_release(T: np.ndarray, X: np.ndarray) -> np.ndarray:
    """Pixels of world points with the released pose and the released (negative-fy) intrinsics."""
    Xc = (np.linalg.inv(T) @ np.column_stack([X, np.ones(len(X))]).T).T[:, :3]
    return np.column_stack([FX * Xc[:, 0] / Xc[:, 2] + CX, FY_RELEASE * Xc[:, 1] / Xc[:, 2] + CY])


def _render(uv: np.ndarray) -> np.ndarray:
    img = np.full((H, W), 10.0)
    for x, y in uv:
        if not (5 <= x < W - 5 and 5 <= y < H - 5):
            continue
        xi, yi = int(x), int(y)
        vv, uu = np.mgrid[yi - 5:yi + 6, xi - 5:xi + 6]
        img[yi - 5:yi + 6, xi - 5:xi + 6] += 230.0 * np.exp(-((uu - x) ** 2 + (vv - y) ** 2) / (2 * 1.2**2))
    g = np.clip(np.rint(img), 0, 255).astype(np.uint8)
    return np.dstack([g, g // 2, g])  # colour, BGR as written by OpenCV


def _centroid(img: np.ndarray, x: float, y: float, r: int = 4) -> np.ndarray:
    xi, yi = int(round(x)), int(round(y))
    p = np.clip(img[yi - r:yi + r + 1, xi - r:xi + r + 1, 0].astype(float) - 10.0, 0, None)
    vv, uu = np.mgrid[yi - r:yi + r + 1, xi - r:xi + r + 1]
    return np.array([(p * uu).sum() / p.sum(), (p * vv).sum() / p.sum()])


def write_icl(root: Path, n: int = 4, gt_name: str = "livingRoom0.gt.freiburg") -> tuple[np.ndarray, np.ndarray]:
    (root / "rgb").mkdir(parents=True)
    (root / "depth").mkdir()
    rng = np.random.default_rng(11)
    X = _scene(rng)
    T = _release_poses(n)
    assoc, gt = [], []
    for i in range(n):
        cv2.imwrite(str(root / "rgb" / f"{i}.png"), _render(_project_release(T[i], X)))
        cv2.imwrite(str(root / "depth" / f"{i}.png"), np.full((H, W), 5000 * 2, np.uint16))  # 2 m
        assoc.append(f"{i} depth/{i}.png {i} rgb/{i}.png")
        if i >= 1:  # the release has poses for ids 1..N-1 only
            q = Rotation.from_matrix(T[i, :3, :3]).as_quat()
            gt.append(f"{i} " + " ".join(f"{v:.9g}" for v in (*T[i, :3, 3], *q)))
    (root / "associations.txt").write_text("\n".join(assoc) + "\n")
    (root / gt_name).write_text("\n".join(gt) + "\n")
    return T, X


def test_layout(tmp_path: Path) -> None:
    root = tmp_path / "living_room_traj0_frei_png"
    T, _ = write_icl(root)
    assert detect_format(root) == "icl-nuim"
    seq = open_sequence(root)
    assert len(seq) == 4 and (seq.width, seq.height) == (640, 480)
    assert (seq.camera.fx, seq.camera.fy, seq.camera.cx, seq.camera.cy) == (481.2, 480.0, 319.5, 239.5)
    np.testing.assert_allclose(seq.timestamps, np.arange(4) / 30.0)
    assert seq[0].pose is None and seq.groundtruth is not None and len(seq.groundtruth) == 3
    f = seq[2]
    assert f.image.shape == (480, 640, 3) and f.depth[0, 0] == pytest.approx(2.0)  # 5000 units per metre
    np.testing.assert_allclose(f.pose, mirror_poses(T[2]), atol=1e-7)
    assert np.linalg.det(f.pose[:3, :3]) == pytest.approx(1.0)  # a proper rotation
    raw = open_sequence(root, mirror_y=False)
    np.testing.assert_allclose(raw[2].pose, T[2], atol=1e-7)


def test_pose_convention_matches_images(tmp_path: Path) -> None:
    """Images rendered with the release's own convention (negative fy) are reproduced by the reader's positive-fy
    camera and mirrored poses: the world point F·X projects onto the dot of X."""
    root = tmp_path / "traj2_frei_png"
    T, X = write_icl(root, gt_name="traj2.gt.freiburg")
    seq = open_sequence(root)
    F = np.diag([1.0, -1.0, 1.0])
    X_mirrored = X @ F.T
    for i in (1, 3):
        f = seq[i]
        uv = CAMERA.project((np.linalg.inv(f.pose) @ np.column_stack([X_mirrored, np.ones(len(X))]).T).T[:, :3])
        inside = CAMERA.in_image(uv, border=6)
        assert inside.sum() >= 20
        err = [np.hypot(*(_centroid(f.image, x, y) - (x, y))) for x, y in uv[inside]]
        assert max(err) < 0.1
        # the released poses with a positive fy would put every point elsewhere
        uv_wrong = CAMERA.project((np.linalg.inv(T[i]) @ np.column_stack([X, np.ones(len(X))]).T).T[:, :3])
        assert np.median(np.abs(uv_wrong[:, 1] - uv[:, 1])) > 20
    # the relative motion of consecutive frames is a rigid motion of the camera (as recovered by VO with fy > 0)
    rel = np.linalg.inv(seq[1].pose) @ seq[3].pose
    rel_release = np.linalg.inv(T[1]) @ T[3]
    np.testing.assert_allclose(rel[:3, 3], F @ rel_release[:3, 3], atol=1e-7)  # y of the motion flips sign


def test_errors_and_info(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    root = tmp_path / "living_room_traj1_frei_png"
    write_icl(root, n=3, gt_name="livingRoom1.gt.freiburg")
    assert main(["info", str(root), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["format"] == "icl-nuim" and info["fy"] == 480.0 and info["groundtruth_frames"] == 2
    assert info["has_depth"] and info["details"]["groundtruth_file"] == "livingRoom1.gt.freiburg"
    (root / "associations.txt").write_text("0 depth/0.png 0 rgb/0.png\n1 depth/1.png rgb/1.png\n")
    with pytest.raises(InputError, match=r"associations.txt:2: expected 'id depth/N.png id rgb/N.png'"):
        open_sequence(root)
    (root / "associations.txt").write_text("0 depth/0.png 0 rgb/0.png\n7 depth/7.png 7 rgb/7.png\n")
    with pytest.raises(InputError, match=r"rgb/7.png: image listed in associations.txt not found"):
        open_sequence(root)
    (root / "associations.txt").write_text("5 depth/0.png 5 rgb/0.png\n")
    with pytest.raises(InputError, match=r"livingRoom1.gt.freiburg: no ground-truth id matches"):
        open_sequence(root)
