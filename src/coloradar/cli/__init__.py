"""Command-line interface: ``coloradar COMMAND …`` (see :mod:`coloradar.cli.main`)."""
