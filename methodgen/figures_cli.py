"""``methodgen figures [--out DIR] [--format png|svg|pdf]`` (placeholder until the plotting layer lands)."""

from __future__ import annotations


def add_parser(sub) -> None:
    """Register the ``figures`` subcommand on ``sub`` (an argparse subparsers object)."""
    return None
