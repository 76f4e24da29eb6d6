"""One module per ``gyrocal`` subcommand (see :data:`gyrocal.kit.cli.COMMANDS`)."""
