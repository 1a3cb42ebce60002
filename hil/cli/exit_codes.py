"""Exit codes of the ``boundswarm`` command, and the error that means bad input.

0 success; 1 failure: a run that was not safe (a collision), or an error that is not the
input's (one line on stderr, ``-v`` adds the traceback); 2 bad input: an option, file,
scenario, config, manifest or run folder that is wrong, with a message naming it;
3 (sitl) a process of the swarm was lost during the run; 4 (sitl) the swarm could not be
run; 130 interrupted.
"""
from __future__ import annotations

EXIT_OK, EXIT_FAILED, EXIT_BAD_INPUT, EXIT_LOST, EXIT_NOT_RUN = 0, 1, 2, 3, 4
EXIT_UNSAFE = EXIT_FAILED
EXIT_INTERRUPTED = 130


class BadInput(ValueError):
    """What the command was given is wrong: a missing file, an invalid value, options that do
    not go together. The message names the option or file."""
