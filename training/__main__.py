"""``python -m training <command>``: see training/cli.py for the command table."""

import sys

from training.cli import main

sys.exit(main(sys.argv[1:]))
