"""``python -m training <command>``: see training/commands/dispatch.py for the command table."""

import sys

from training.commands.dispatch import main

sys.exit(main(sys.argv[1:]))
