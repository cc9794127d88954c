"""One module per `fdi` subcommand: HELP, configure(parser), run(args) -> int."""
