"""Artifact store: one directory per job under a root (shared when workers are on many machines).

File names are ours, never the uploader's; writes go to a temporary name and are renamed
into place, so a crash leaves no half-written artifact behind.
"""

from __future__ import annotations

import os
import re
import shutil
import tempfile
from pathlib import Path
from typing import BinaryIO

CHUNK = 1 << 20


class UploadTooLargeError(Exception):
    def __init__(self, limit: int) -> None:
        super().__init__(f"upload exceeds the limit of {limit} bytes")
        self.limit = limit


def safe_name(filename: str | None) -> str:
    """The base name of ``filename`` with only letters, digits, ``.``, ``_`` and ``-`` kept and
    no leading dot ('' if nothing is left)."""
    base = re.split(r"[\\/]", filename or "")[-1]
    return re.sub(r"[^A-Za-z0-9._-]", "_", base).lstrip(".")[:120]


class ArtifactStore:
    def __init__(self, root: Path) -> None:
        self.root = Path(root)
        self.root.mkdir(parents=True, exist_ok=True)

    def job_dir(self, job_id: str) -> Path:
        if not job_id.isalnum():
            raise ValueError("bad job id")
        return self.root / job_id

    def path(self, job_id: str, name: str) -> Path:
        return self.job_dir(job_id) / name

    def save_stream(self, job_id: str, name: str, src: BinaryIO, *, max_bytes: int) -> Path:
        """Copy ``src`` to the job's ``name`` in chunks, failing past ``max_bytes``."""
        target = self.path(job_id, name)
        target.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=target.parent, prefix=".upload-")
        written = 0
        try:
            with os.fdopen(fd, "wb") as out:
                while chunk := src.read(CHUNK):
                    written += len(chunk)
                    if written > max_bytes:
                        raise UploadTooLargeError(max_bytes)
                    out.write(chunk)
            os.replace(tmp, target)
        except BaseException:
            Path(tmp).unlink(missing_ok=True)
            raise
        return target

    def save_upload(
        self, job_id: str, field: str, index: int, filename: str | None, src: BinaryIO, *, max_bytes: int
    ) -> Path:
        """Store one uploaded file as ``uploads/<field>/<name>``: the uploader's name reduced to
        a safe base name (never a path), so a kind can match names a manifest lists."""
        name = safe_name(filename) or f"{field}-{index}"
        folder = f"uploads/{field}"
        if self.path(job_id, f"{folder}/{name}").exists():
            name = f"{index}-{name}"
        return self.save_stream(job_id, f"{folder}/{name}", src, max_bytes=max_bytes)

    def save_bytes(self, job_id: str, name: str, data: bytes) -> Path:
        target = self.path(job_id, name)
        target.parent.mkdir(parents=True, exist_ok=True)
        tmp = target.with_name(f".{name}.tmp")
        tmp.write_bytes(data)
        os.replace(tmp, target)
        return target

    def temporary(self, job_id: str, name: str) -> Path:
        """A path to write ``name`` to before :meth:`publish` moves it into place."""
        target = self.path(job_id, name)
        target.parent.mkdir(parents=True, exist_ok=True)
        return target.with_name(f".{name}.tmp")

    def publish(self, job_id: str, name: str) -> Path:
        target = self.path(job_id, name)
        os.replace(self.temporary(job_id, name), target)
        return target

    def delete(self, job_id: str) -> None:
        shutil.rmtree(self.job_dir(job_id), ignore_errors=True)
