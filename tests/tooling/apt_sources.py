"""The Debian archive this machine's apt uses, read from its sources lists.

One-line ``*.list`` files (``deb [options] URI suite components``) and deb822 ``*.sources``
files (``Types:``, ``URIs:``, ``Enabled:``). A Debian archive is a ``deb`` source whose URI
path ends in ``/debian`` (the archive's root on every Debian mirror); security and
third-party repositories are not.
"""
from __future__ import annotations

from pathlib import Path
from urllib.parse import urlsplit

APT_DIR = Path("/etc/apt")


class NoDebianSource(LookupError):
    """None of the sources lists names a Debian archive."""


def source_files(apt_dir: Path = APT_DIR) -> list[Path]:
    """``sources.list`` and the ``sources.list.d`` files apt reads, in apt's order."""
    parts = apt_dir / "sources.list.d"
    listed = sorted(parts.glob("*.list")) + sorted(parts.glob("*.sources")) \
        if parts.is_dir() else []
    return [f for f in [apt_dir / "sources.list", *listed] if f.is_file()]


def one_line_uris(text: str) -> list[str]:
    """The URIs of the ``deb`` lines of a one-line-style sources list."""
    uris = []
    for line in text.splitlines():
        words = line.split("#", 1)[0].split()
        if not words or words[0] != "deb":
            continue
        rest = words[1:]
        if rest and rest[0].startswith("["):          # [arch=amd64 signed-by=...]
            while rest and not rest[0].endswith("]"):
                rest = rest[1:]
            rest = rest[1:]
        if rest:
            uris.append(rest[0])
    return uris


def deb822_uris(text: str) -> list[str]:
    """The URIs of the enabled ``deb`` stanzas of a deb822 ``.sources`` file."""
    uris = []
    for stanza in text.split("\n\n"):
        fields: dict[str, str] = {}
        key = None
        for line in stanza.splitlines():
            if line.startswith("#") or not line.strip():
                continue
            if line[0].isspace() and key:              # continuation line
                fields[key] += " " + line.strip()
            elif ":" in line:
                key, value = line.split(":", 1)
                key = key.strip().lower()
                fields[key] = value.strip()
        if "deb" in fields.get("types", "").split() and \
                fields.get("enabled", "yes").lower() != "no":
            uris += fields.get("uris", "").split()
    return uris


def is_debian_archive(uri: str) -> bool:
    return urlsplit(uri).path.rstrip("/").endswith("/debian")


def debian_mirror(apt_dir: Path = APT_DIR) -> str:
    """The first Debian archive URI in apt's sources (no trailing slash)."""
    files = source_files(apt_dir)
    for f in files:
        text = f.read_text(errors="replace")
        uris = deb822_uris(text) if f.suffix == ".sources" else one_line_uris(text)
        for uri in uris:
            if is_debian_archive(uri):
                return uri.rstrip("/")
    read = ", ".join(map(str, files)) or f"no sources list under {apt_dir}"
    raise NoDebianSource(f"no Debian archive (a deb URI ending in /debian) in apt's "
                         f"sources ({read})")
