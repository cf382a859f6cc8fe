"""``methodgen sweep SPEC [--scheduler ADDRESS] [--workers N]`` (placeholder until the sweep layer lands)."""

from __future__ import annotations


def add_parser(sub) -> None:
    """Register the ``sweep`` subcommand on ``sub`` (an argparse subparsers object)."""
    return None
