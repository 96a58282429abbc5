"""What a file is, from its first bytes: names are not trusted (an upload's name is the
uploader's, and a file called .ply may be anything)."""

from __future__ import annotations

from pathlib import Path

_MAGIC = (
    (b"ply\n", "ply"),
    (b"ply\r\n", "ply"),
    (b"PK\x03\x04", "zip"),  # NPZ archives are zips too
    (b"PK\x05\x06", "zip"),  # an empty zip
    (b"\x89PNG\r\n\x1a\n", "png"),
    (b"II*\x00", "tiff"),
    (b"MM\x00*", "tiff"),
    (b"\xff\xd8\xff", "jpeg"),
)


def sniff(path: Path) -> str | None:
    """'ply', 'zip', 'png', 'tiff', 'jpeg', 'json' or 'text' from the first bytes; None for
    anything else (binary of an unknown kind, or an empty file)."""
    with open(path, "rb") as fh:
        head = fh.read(512)
    for magic, kind in _MAGIC:
        if head.startswith(magic):
            return kind
    text = head.removeprefix(b"\xef\xbb\xbf").lstrip()
    if text.startswith((b"{", b"[")):
        return "json"
    if text and _is_text(head):
        return "text"
    return None


def _is_text(head: bytes) -> bool:
    try:
        head.decode("utf-8")
    except UnicodeDecodeError as exc:
        return exc.start >= len(head) - 3  # a multi-byte character cut by the 512-byte window
    return b"\x00" not in head
