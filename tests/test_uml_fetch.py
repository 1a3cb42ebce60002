"""Unpacking the Debian packages of a newer UML kernel (tooling.uml.fetch), without the network."""
import io
import os
import tarfile

import pytest
from tooling import uml


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


def tar_of(*members: tuple[str, str | bytes]) -> bytes:
    """An xz tar of (name, body) files and (name, "->target") symlinks, in order."""
    buf = io.BytesIO()
    with tarfile.open(fileobj=buf, mode="w:xz") as tar:
        for name, body in members:
            info = tarfile.TarInfo(name)
            if isinstance(body, str):
                info.type, info.linkname = tarfile.SYMTYPE, body.removeprefix("->")
                tar.addfile(info)
            else:
                info.size = len(body)
                tar.addfile(info, io.BytesIO(body))
    return buf.getvalue()


@pytest.fixture(params=[False, True], ids=["this-python", "older-python"])
def dest(request, tmp_path, monkeypatch):
    """An empty destination beside an empty ``outside``; with tarfile's filters hidden in
    the second run (the check of a Python before 3.11.4, as Debian 12's 3.11.2)."""
    if request.param:
        monkeypatch.delattr(tarfile, "tar_filter", raising=False)
    (tmp_path / "outside").mkdir()
    (tmp_path / "dest").mkdir()
    return tmp_path / "dest"


def test_a_member_that_would_land_outside_is_refused(dest):
    outside = dest.parent / "outside"
    for data in (tar_of(("../outside/x", b"x")),
                 tar_of(("./usr/lib", f"->{outside}"), ("./usr/lib/x", b"x")),
                 tar_of(("./up", "->../outside"), ("./up/x", b"x"))):
        with pytest.raises(ValueError, match="outside"):
            uml._extract_deb(ar_archive({"data.tar.xz": data}), dest)
        assert not list(outside.iterdir())


def test_absolute_names_land_inside_and_absolute_links_are_kept(dest):
    data = tar_of(("/etc/motd", b"hi"), ("./lib64/ld.so", "->/lib/x86_64-linux-gnu/ld.so"))
    uml._extract_deb(ar_archive({"data.tar.xz": data}), dest)
    assert (dest / "etc/motd").read_bytes() == b"hi"          # as in libc6's data.tar
    assert os.readlink(dest / "lib64/ld.so") == "/lib/x86_64-linux-gnu/ld.so"
