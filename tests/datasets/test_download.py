"""`dmtrack download`: arguments, URL plans, errors, resume and unpacking — without network (urlopen is faked)."""

from __future__ import annotations

import argparse
import hashlib
import io
import urllib.error
import urllib.request
import zipfile
from pathlib import Path

import pytest

from dmtrack.datasets import download as dl
from dmtrack.datasets.cli_download import add_download_parser
from dmtrack.errors import InputError


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="dmtrack")
    sub = p.add_subparsers(dest="command")
    add_download_parser(sub)
    return p


def _run(argv: list[str]) -> int:
    args = _parser().parse_args(argv)
    return args.func(args)


def test_unknown_dataset_and_sequence_list_valid_ones() -> None:
    with pytest.raises(InputError, match=r"unknown dataset 'kiti'; known datasets: tum-monovo, tum-rgbd, kitti, "
                                         r"euroc, icl-nuim, 7scenes"):
        dl.plan("kiti", "00")
    with pytest.raises(InputError,
                       match=r"unknown euroc sequence 'MH_06'; known sequences: MH_01_easy, .*V2_03_difficult"):
        dl.plan("euroc", "MH_06")
    with pytest.raises(InputError, match=r"unknown kitti sequence '22'; known sequences: 00, 01, .*, 21"):
        dl.plan("kitti", "22")


def test_plans() -> None:
    assert [a.url for a in dl.plan("tum-monovo", "7")] == ["https://vision.in.tum.de/mono/dataset/sequence_07.zip"]
    assert dl.plan("tum-monovo", "sequence_50")[0].filename == "sequence_50.zip"
    (a,) = dl.plan("tum-rgbd", "fr1/xyz")
    assert a.url == "https://vision.in.tum.de/rgbd/dataset/freiburg1/rgbd_dataset_freiburg1_xyz.tgz"
    kitti = dl.plan("kitti", "6")
    assert [a.filename for a in kitti] == ["data_odometry_gray.zip", "data_odometry_calib.zip",
                                           "data_odometry_poses.zip"]
    assert kitti[0].members == ("dataset/sequences/06/",) and kitti[2].members == ("dataset/poses/06.txt",)
    assert len(dl.plan("kitti", "15")) == 2  # no public poses for the test sequences 11–21
    assert "registration" in dl.DATASETS["kitti"].note
    assert dl.plan("euroc", "V2_02_medium")[0].url.endswith("/vicon_room2/V2_02_medium/V2_02_medium.zip")
    assert dl.plan("icl-nuim", "lr_kt2")[0].url == "http://www.doc.ic.ac.uk/~ahanda/living_room_traj2_frei_png.tar.gz"
    assert dl.plan("icl-nuim", "of_kt0")[0].filename == "traj0_frei_png.tar.gz"
    assert dl.plan("7scenes", "redkitchen")[0].url.endswith("/redkitchen.zip")


def test_network_failure_names_the_url(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    def no_network(*args, **kwargs):
        raise urllib.error.URLError("[Errno -3] Temporary failure in name resolution")

    monkeypatch.setattr(urllib.request, "urlopen", no_network)
    with pytest.raises(dl.DownloadError, match=r"cannot reach https://vision.in.tum.de/mono/dataset/sequence_03.zip "
                                               r"\(\[Errno -3\] Temporary failure in name resolution\)"):
        dl.download("tum-monovo", "03", tmp_path / "out")
    assert not list((tmp_path / "out").glob("*.zip"))

    def http_404(req, *args, **kwargs):
        raise urllib.error.HTTPError(req.full_url, 404, "Not Found", {}, None)

    monkeypatch.setattr(urllib.request, "urlopen", http_404)
    with pytest.raises(dl.DownloadError, match=r"HTTP 404 Not Found for http://robotics.ethz.ch/"):
        dl.download("euroc", "MH_01_easy", tmp_path / "out")


class _FakeResponse(io.BytesIO):
    def __init__(self, data: bytes, status: int) -> None:
        super().__init__(data)
        self.status = status
        self.headers = {"Content-Length": str(len(data))}


def _zip_bytes() -> bytes:
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as z:
        z.writestr("sequence_09/times.txt", "00000 1.0 10\n")
        z.writestr("sequence_09/camera.txt", "0.5 0.5 0.5 0.5 0.9\n10 10\ncrop\n10 10\n")
    return buf.getvalue()


def test_resume_with_range_and_unpack(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    payload = _zip_bytes()
    out = tmp_path / "data"
    out.mkdir()
    (out / "sequence_09.zip.part").write_bytes(payload[:100])  # an interrupted earlier download
    seen: list[str | None] = []

    def fake_urlopen(req, timeout=None):
        rng = req.get_header("Range")
        seen.append(rng)
        start = int(rng.split("=")[1].rstrip("-")) if rng else 0
        return _FakeResponse(payload[start:], 206 if rng else 200)

    monkeypatch.setattr(urllib.request, "urlopen", fake_urlopen)
    progress: list[tuple[int, int | None]] = []
    dl.download("tum-monovo", "9", out, progress=lambda d, t: progress.append((d, t)))
    assert seen == ["bytes=100-"]
    assert (out / "sequence_09.zip").read_bytes() == payload and not (out / "sequence_09.zip.part").exists()
    assert (out / "sequence_09" / "times.txt").read_text() == "00000 1.0 10\n"
    assert progress[-1] == (len(payload), len(payload))
    # a complete archive is not fetched again
    dl.download("tum-monovo", "9", out)
    assert seen == ["bytes=100-"]


def test_server_ignoring_range_restarts(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    payload = _zip_bytes()
    (tmp_path / "sequence_09.zip.part").write_bytes(b"x" * 50)
    monkeypatch.setattr(urllib.request, "urlopen", lambda req, timeout=None: _FakeResponse(payload, 200))
    dl.download("tum-monovo", "09", tmp_path, extract=False)
    assert (tmp_path / "sequence_09.zip").read_bytes() == payload


def test_checksum_mismatch_and_member_filter(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as z:
        z.writestr("dataset/sequences/06/times.txt", "0.0\n")
        z.writestr("dataset/sequences/07/times.txt", "0.0\n")
    payload = buf.getvalue()
    monkeypatch.setattr(urllib.request, "urlopen", lambda req, timeout=None: _FakeResponse(payload, 200))
    good = dl.Archive("https://example.org/a.zip", "a.zip", sha256=hashlib.sha256(payload).hexdigest(),
                      members=("dataset/sequences/06/",))
    path = dl._fetch(good, tmp_path / "a.zip", None)
    dl._extract(path, tmp_path, good.members)
    assert (tmp_path / "dataset/sequences/06/times.txt").is_file()
    assert not (tmp_path / "dataset/sequences/07").exists()
    bad = dl.Archive("https://example.org/b.zip", "b.zip", md5="0" * 32)
    with pytest.raises(dl.DownloadError, match=r"md5 checksum mismatch for https://example.org/b.zip"):
        dl._fetch(bad, tmp_path / "b.zip", None)
    assert not (tmp_path / "b.zip").exists() and not (tmp_path / "b.zip.part").exists()


def test_cli(tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    assert _run(["download", "--list"]) == 0
    out = capsys.readouterr().out
    assert "tum-monovo" in out and "kitti" in out and "registration" in out
    assert _run(["download", "icl-nuim", "--list"]) == 0
    assert capsys.readouterr().out.split() == ["lr_kt0", "lr_kt1", "lr_kt2", "lr_kt3", "of_kt0", "of_kt1",
                                               "of_kt2", "of_kt3"]
    assert _run(["download", "kitti", "00", str(tmp_path), "--dry-run"]) == 0
    err = capsys.readouterr().err
    assert "note: KITTI requires registration" in err and "data_odometry_gray.zip" in err
    with pytest.raises(InputError, match="unknown dataset 'nope'"):
        _run(["download", "nope", "1", str(tmp_path)])
    monkeypatch.setattr(urllib.request, "urlopen",
                        lambda *a, **k: (_ for _ in ()).throw(urllib.error.URLError("offline")))
    with pytest.raises(dl.DownloadError, match="cannot reach https://vision.in.tum.de/rgbd/dataset/freiburg3/"):
        _run(["download", "tum-rgbd", "freiburg3_long_office_household", str(tmp_path), "--quiet"])
