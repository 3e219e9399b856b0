"""Downloading an official weight file: resumable, checksum-verified (``python -m dmtrack.features.weights``).

The file is streamed into ``NAME.part`` (an interrupted download resumes from there with an HTTP Range request)
and renamed only after its checksum passed; a file extracted from a downloaded archive and the ``.sha256`` note
recorded for files without a published checksum are written atomically (:mod:`dmtrack.io.atomic`).
"""

from __future__ import annotations

import os
import tarfile
import urllib.error
import urllib.request
from collections.abc import Callable
from pathlib import Path

from dmtrack.errors import InputError
from dmtrack.features.weights.catalogue import (
    DownloadError,
    file_digest,
    user_weights_dir,
    verify_checksum,
    weight_info,
)
from dmtrack.io.atomic import write_bytes, write_text


def _fetch(url: str, part: Path, timeout: float, progress: Callable[[int, int | None], None] | None) -> None:
    """Download ``url`` into ``part``, resuming from its current size with an HTTP Range request."""
    start = part.stat().st_size if part.exists() else 0
    req = urllib.request.Request(url, headers={"User-Agent": "dmtrack"})
    if start:
        req.add_header("Range", f"bytes={start}-")
    try:
        resp = urllib.request.urlopen(req, timeout=timeout)
    except urllib.error.HTTPError as exc:
        if exc.code == 416 and start:  # already complete
            return
        raise DownloadError(f"cannot download {url}: HTTP {exc.code} {exc.reason}") from exc
    except (urllib.error.URLError, OSError, ValueError) as exc:
        reason = getattr(exc, "reason", exc)
        raise DownloadError(f"cannot download {url}: {reason}") from exc
    with resp:
        status = getattr(resp, "status", 200)
        mode = "ab" if (start and status == 206) else "wb"
        done = start if mode == "ab" else 0
        length = resp.headers.get("Content-Length") if hasattr(resp, "headers") else None
        total = done + int(length) if length and length.isdigit() else None
        try:
            with open(part, mode) as out:
                while True:
                    block = resp.read(1 << 20)
                    if not block:
                        break
                    out.write(block)
                    done += len(block)
                    if progress is not None:
                        progress(done, total)
        except OSError as exc:
            raise DownloadError(f"download of {url} interrupted after {done} bytes: {exc}") from exc
    if total is not None and done < total:
        raise DownloadError(f"download of {url} incomplete: {done} of {total} bytes (run again to resume)")


def download(
    name: str,
    dest: str | os.PathLike[str] | None = None,
    *,
    timeout: float = 60.0,
    progress: Callable[[int, int | None], None] | None = None,
) -> Path:
    """Download the official weight file ``name`` and verify its checksum.

    The file is written to ``<dest>/<filename>.part`` first (an interrupted download resumes from there with an
    HTTP Range request), checked, then renamed.  For entries distributed inside an archive (the "siam"
    networks) the archive is downloaded and the member extracted.

    Parameters
    ----------
    name
        Catalogue key (see ``python -m dmtrack.features.weights list``).
    dest
        Target directory (created) or target file path ending in the entry's suffix; default
        :func:`user_weights_dir`.
    timeout
        Socket timeout in seconds.
    progress
        Optional ``progress(bytes_done, bytes_total_or_None)`` callback.

    Returns
    -------
    Path
        The downloaded, verified file.

    Raises
    ------
    InputError
        Unknown ``name``.
    DownloadError
        Network failure, HTTP error, incomplete transfer, checksum mismatch or missing archive member.
    """
    info = weight_info(name)
    if timeout <= 0:
        raise InputError(f"timeout must be > 0, got {timeout}")
    dest_path = user_weights_dir() if dest is None else Path(dest).expanduser()
    if dest_path.suffix and dest_path.suffix == Path(info.filename).suffix and not dest_path.is_dir():
        target = dest_path
    else:
        target = dest_path / info.filename
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise DownloadError(f"cannot create the weights directory {target.parent}: {exc}") from exc
    if info.archive_member is None:
        part = target.with_name(target.name + ".part")
        _fetch(info.url, part, timeout, progress)
        try:
            sha = verify_checksum(part, info)
        except DownloadError:
            part.unlink(missing_ok=True)
            raise
        part.replace(target)
    else:
        archive = target.with_name(Path(info.url).name + ".part")
        _fetch(info.url, archive, timeout, progress)
        try:
            with tarfile.open(archive, "r:*") as tar:
                members = [m for m in tar.getmembers() if m.isfile() and m.name.endswith(info.archive_member)]
                if not members:
                    names = [m.name for m in tar.getmembers() if m.isfile()][:30]
                    raise DownloadError(
                        f"{info.url}: no member ending in {info.archive_member} (members: {', '.join(names)})"
                    )
                src = tar.extractfile(members[0])
                assert src is not None
                data = src.read()
        except (tarfile.TarError, OSError) as exc:
            raise DownloadError(f"cannot read the archive downloaded from {info.url}: {exc}") from exc
        write_bytes(target, data)
        sha = verify_checksum(target, info)
        archive.unlink(missing_ok=True)
    if sha is None:  # nothing published to check against: record what was received
        sha = file_digest(target)
        write_text(target.with_name(target.name + ".sha256"), f"{sha}  {target.name}\n")
    return target
