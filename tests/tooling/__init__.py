"""Tooling of the tests and benchmarks, kept out of the installed package.

    uml.py          a shell script inside User-Mode Linux (SocketCAN, netem);
                    ``python -m tooling.uml ensure`` (make test)
    apt_sources.py  the Debian archive this machine's apt uses (where uml fetches a kernel)
    link_delay.py   a delaying TCP relay (the multi-host tests' slow link)

Importable by the tests (pytest puts tests/ on the path) and, with tests/ on PYTHONPATH or
sys.path, by ``python -m tooling.<name>`` and ``bench/``.
"""
