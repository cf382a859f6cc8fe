"""``methodgen verify SCENE [--method M] [--json]`` (placeholder until the verification layer lands)."""

from __future__ import annotations


def add_parser(sub) -> None:
    """Register the ``verify`` subcommand on ``sub`` (an argparse subparsers object)."""
    return None
