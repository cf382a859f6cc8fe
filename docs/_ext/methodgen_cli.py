"""``.. methodgen-cli::`` — the command-line reference, printed from the parser itself.

The directive asks :func:`methodgen.app.cli.make_parser` for the ``--help`` text of the program
and of every sub-command, so the reference can never disagree with the CLI.
"""

from __future__ import annotations

import contextlib
import io
import os
import re

from docutils import nodes
from docutils.parsers.rst import Directive


class MethodgenCli(Directive):
    has_content = False

    def run(self):
        from methodgen.app.cli import make_parser

        os.environ["COLUMNS"] = "100"   # the same wrapping on every machine
        parser = make_parser()
        out = []
        top = nodes.section(ids=["cli-methodgen"])
        top += nodes.title(text="methodgen")
        top += nodes.literal_block(text=parser.format_help())
        out.append(top)
        # The commands, as the usage line lists them ({run,verify,...}); each one's help is what
        # `methodgen COMMAND --help` prints (argparse's public route: it prints and exits).
        names = re.search(r"\{([a-z,-]+)\}", parser.format_usage()).group(1).split(",")
        for name in names:
            buf = io.StringIO()
            with contextlib.redirect_stdout(buf), contextlib.suppress(SystemExit):
                make_parser().parse_args([name, "--help"])
            sec = nodes.section(ids=[f"cli-{name}"])
            sec += nodes.title(text=f"methodgen {name}")
            sec += nodes.literal_block(text=buf.getvalue())
            out.append(sec)
        return out


def setup(app):
    app.add_directive("methodgen-cli", MethodgenCli)
    return {"version": "1", "parallel_read_safe": True, "parallel_write_safe": True}
