"""One module per ``gyrocal`` subcommand (see :data:`kit.cli.COMMANDS`)."""
