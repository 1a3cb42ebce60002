"""Unpacking the Debian packages of a newer UML kernel (hil.uml.fetch), without the network."""
import io
import tarfile

import pytest

from hil import uml


def ar_archive(members: dict[str, bytes]) -> bytes:
    out = b"!<arch>\n"
    for name, body in members.items():
        header = f"{name + '/':<16}{0:<12}{0:<6}{0:<6}{'100644':<8}{len(body):<10}`\n"
        out += header.encode() + body + (b"\n" if len(body) % 2 else b"")
    return out


def data_tar(files: dict[str, bytes]) -> bytes:
    buf = io.BytesIO()
    with tarfile.open(fileobj=buf, mode="w:xz") as tar:
        for path, body in files.items():
            info = tarfile.TarInfo(path)
            info.size = len(body)
            tar.addfile(info, io.BytesIO(body))
    return buf.getvalue()


def test_deb_data_is_unpacked(tmp_path):
    deb = ar_archive({"debian-binary": b"2.0\n", "control.tar.xz": data_tar({"./control": b"x"}),
                      "data.tar.xz": data_tar({"./usr/bin/linux.uml": b"ELF"})})
    uml._extract_deb(deb, tmp_path)
    assert (tmp_path / "usr/bin/linux.uml").read_bytes() == b"ELF"
    assert not (tmp_path / "control").exists()


def test_a_file_that_is_not_a_deb_is_refused(tmp_path):
    with pytest.raises(ValueError, match="not a Debian package"):
        uml._extract_deb(b"<html>404</html>", tmp_path)
    with pytest.raises(ValueError, match="without data.tar"):
        uml._extract_deb(ar_archive({"debian-binary": b"2.0\n"}), tmp_path)
