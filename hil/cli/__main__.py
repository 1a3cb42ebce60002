"""``python -m hil.cli``: the ``boundswarm`` command with this interpreter (how the SITL
launcher and the tests start its subcommands)."""
import sys

from hil.cli import main

if __name__ == "__main__":
    sys.exit(main())
