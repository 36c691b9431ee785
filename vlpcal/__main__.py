"""``python -m vlpcal`` is the ``vlpcal`` command."""

from .cli import main

main(prog_name="vlpcal")
