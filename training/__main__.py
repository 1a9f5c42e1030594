"""``python -m training <command>``: see training/commands/dispatch.py for the command table."""

import os
import sys

from exporters.cli_io import EXIT_INTERRUPTED
from training.commands.dispatch import main


def _leave(code: int) -> None:
    """End the process with ``code``.  After Ctrl-C the command has printed its one line and closed what it keeps;
    the interpreter's teardown can then still meet what the interrupt cut short (numba's parallel kernel threads
    mid-walk) and die of a segmentation fault (exit -11 instead of 130), so an interrupted run leaves without that
    teardown."""
    if code != EXIT_INTERRUPTED:
        sys.exit(code)
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)


if __name__ == "__main__":  # imported (by the documentation's API pages), it runs nothing
    _leave(main(sys.argv[1:]))
