"""``python3 -m hptrack COMMAND ...``: the ``hptrack`` command line."""

from hptrack.cli.app import main

main()
