"""``python -m dicetrace``: the ``dicetrace`` command, for an environment whose scripts are not on PATH."""

from dicetrace.cli import main

main()
