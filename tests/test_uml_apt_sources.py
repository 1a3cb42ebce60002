"""The Debian mirror of the UML fetch comes from the machine's apt sources (both formats)."""
from pathlib import Path

import pytest
from tooling import uml
from tooling.apt_sources import NoDebianSource, deb822_uris, debian_mirror, one_line_uris

ONE_LINE = """\
# the security archive and a third-party repository come first
deb http://security.example/debian-security bookworm-security main
deb [arch=amd64 signed-by=/usr/share/keyrings/x.gpg] https://repo.example/apt stable main
deb-src http://src.example/debian bookworm main
#deb http://commented.example/debian bookworm main
deb [ arch=amd64 ] http://mirror.example/debian/ bookworm main contrib   # the one
deb http://later.example/debian bookworm main
"""

DEB822 = """\
Types: deb
URIs: https://repo.example/apt
Suites: stable
Components: main

Types: deb
URIs: http://disabled.example/debian
Suites: bookworm
Components: main
Enabled: no

Types: deb-src
URIs: http://src.example/debian
Suites: bookworm
Components: main

# a comment before the stanza
Types: deb deb-src
URIs: http://security.example/debian-security
 https://mirror822.example/pub/debian
Suites: bookworm
Components: main
Signed-By: /usr/share/keyrings/debian-archive-keyring.gpg
"""


def apt_dir(tmp_path: Path, files: dict[str, str]) -> Path:
    (tmp_path / "sources.list.d").mkdir()
    for name, text in files.items():
        (tmp_path / name).write_text(text)
    return tmp_path


def test_one_line_format():
    assert one_line_uris(ONE_LINE) == ["http://security.example/debian-security",
                                       "https://repo.example/apt",
                                       "http://mirror.example/debian/",
                                       "http://later.example/debian"]


def test_deb822_format():
    assert deb822_uris(DEB822) == ["https://repo.example/apt",
                                   "http://security.example/debian-security",
                                   "https://mirror822.example/pub/debian"]


@pytest.mark.parametrize("files, mirror", [
    ({"sources.list": ONE_LINE}, "http://mirror.example/debian"),
    ({"sources.list.d/debian.sources": DEB822}, "https://mirror822.example/pub/debian"),
    # sources.list is read first, then sources.list.d in name order
    ({"sources.list": "", "sources.list.d/b.list": ONE_LINE,
      "sources.list.d/a.sources": DEB822}, "http://mirror.example/debian"),
    ({"sources.list.d/a.sources": DEB822, "sources.list.d/z.sources":
      "Types: deb\nURIs: http://z.example/debian\nSuites: sid\nComponents: main\n"},
     "https://mirror822.example/pub/debian"),
])
def test_the_first_debian_archive_is_the_mirror(tmp_path, files, mirror):
    assert debian_mirror(apt_dir(tmp_path, files)) == mirror


def test_no_debian_archive_is_an_error_naming_the_files(tmp_path):
    d = apt_dir(tmp_path, {"sources.list": "deb https://repo.example/apt stable main\n",
                           "sources.list.d/x.sources": DEB822.split("\n\n")[0] + "\n",
                           "sources.list.d/off.list.disabled": ONE_LINE})
    with pytest.raises(NoDebianSource) as exc:
        debian_mirror(d)
    assert str(d / "sources.list") in str(exc.value)
    assert str(d / "sources.list.d" / "x.sources") in str(exc.value)
    assert "off.list.disabled" not in str(exc.value)
    with pytest.raises(NoDebianSource, match="no sources list under"):
        debian_mirror(tmp_path / "empty")


def test_the_fetch_takes_its_mirror_from_apt(tmp_path, monkeypatch):
    """No mirror is written into the code: fetch asks the apt sources for it."""
    asked = []

    def index(mirror, suite):
        asked.append((mirror, suite))
        raise OSError("offline")
    monkeypatch.setattr(uml, "debian_mirror", lambda: "http://apt.example/debian")
    monkeypatch.setattr(uml, "_packages_index", index)
    monkeypatch.setattr(uml.shutil, "which", lambda name, path=None: "/usr/bin/" + name)
    with pytest.raises(OSError, match="offline"):
        uml.fetch(tmp_path / "uml")
    assert asked == [("http://apt.example/debian", uml.SUITE)]
    assert not hasattr(uml, "MIRROR")
