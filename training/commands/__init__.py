"""The command line of ``python -m training`` (docs/contracts.md §2): the top layer of ``training``.

:mod:`training.commands.dispatch` holds the command table and dispatches; every other module here is one
command (``main(argv: list[str]) -> int`` with its own argparse parser) that parses options and calls the
science packages below it (``training.sim``, ``.data``, ``.fit``, ``.train``, ``.export``, ``.validate``,
...), which never import a command.  :mod:`training.commands.options` holds the argparse types they share.
"""
