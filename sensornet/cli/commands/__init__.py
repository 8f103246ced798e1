"""One module per command (or per few that share everything), loaded by name from
:data:`sensornet.cli.parser.COMMANDS` only when that command runs: each imports what it needs
at its top, and ``sensornet --help`` loads none of them."""
