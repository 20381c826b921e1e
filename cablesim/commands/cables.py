"""``cablesim cables``: the catalogue of cable kinds (:mod:`cablesim.cables`), one line
per kind beginning with its name, then its parameters; ``--cable KIND`` on ``scene``,
``explore``, ``episode``, ``twin``, ``dataset`` and ``benchmark`` makes every cable of that
kind, ``--set episode.scene.hoses.kinds='["rope","thin_wire"]'`` (or ``hoses.kinds`` in a
config file) one kind per cable.  ``--patterns`` lists the surface patterns instead (``--pattern
NAME`` on the same commands, ``hoses.pattern`` or ``hoses.patterns`` in a config)."""

from __future__ import annotations

import argparse
import json

from cablesim.cables import CABLE_KINDS, DEFAULT_KIND, PATTERNS
from cablesim.config import to_dict


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--json", action="store_true", help="every parameter of every kind as JSON instead"
    )
    p.add_argument(
        "--patterns",
        action="store_true",
        help="the surface patterns instead, one line each beginning with its name",
    )


def run(args: argparse.Namespace) -> int:
    if args.patterns:
        if args.json:
            print(json.dumps(PATTERNS, indent=1))
            return 0
        for name, what in PATTERNS.items():
            print(f"{name:<8} {what}")
        return 0
    if args.json:
        print(json.dumps({name: to_dict(k) for name, k in CABLE_KINDS.items()}, indent=1))
        return 0
    for kind in CABLE_KINDS.values():
        print(kind.line() + (" (default)" if kind.name == DEFAULT_KIND else ""))
    return 0
