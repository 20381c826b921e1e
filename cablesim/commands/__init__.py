"""Implementations of the ``cablesim`` subcommands, one module each (see ``cablesim.cli``)."""
