"""``python -m acps``: the acps command line."""

from acps._cli import main

main()
