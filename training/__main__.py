"""``python -m training <command>``: see training/commands/dispatch.py for the command table."""

import sys

from training.commands.dispatch import main

if __name__ == "__main__":  # imported (by the documentation's API pages), it runs nothing
    sys.exit(main(sys.argv[1:]))
