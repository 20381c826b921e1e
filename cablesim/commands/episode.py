"""``cablesim episode``: implemented in :mod:`cablesim.episode.cli`."""

from cablesim.episode.cli import __doc__, add_arguments, run  # noqa: F401
