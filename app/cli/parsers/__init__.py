"""The command line's parsers, one module a group of commands: app.cli.main builds them for the help."""
