"""``methodgen figures [--out DIR] [--format png|svg|pdf] [--json]``.

Reproduces the lecture notes' Figures 1 and 2 (see :mod:`methodgen.app.figures`),
checks their captions and writes the images into ``generated/figures/`` (the
committed copies the docs show) or ``--out``.  Exit status 0 when every
caption check passes, 1 when one fails (the images are written either way so
the failure can be looked at), 2 for bad input or a missing matplotlib.
"""

from __future__ import annotations

import time
from pathlib import Path

from ...errors import InputError
from .common import expand_user


def _default_out() -> Path:
    from ...codegen.build import generated_dir

    gen = generated_dir()
    if gen is None:
        raise InputError("no generated/ folder found (not a source checkout); pass --out DIR")
    return gen / "figures"


def _summary(checks: dict) -> list[str]:
    c1, c2 = checks["figure1"], checks["figure2"]
    lines = ["Figure 1 (linear, implicit midpoint):"]
    for panel in ("left", "right"):
        c = c1[panel]
        a = c["angle"]
        lines.append(f"  h = {c['h']:g}, {c['steps']} steps: max |H−H0|/H0 = {c['energy_max_rel_error']:.2e}; "
                     f"angle/step {abs(a['measured_mean']):.15f} vs 2·arctan(hω/2) = {abs(a['expected']):.15f} "
                     f"(max dev {a['max_deviation']:.1e}); exact hω = {abs(c['exact_angle']):.6f}  "
                     f"[{'ok' if c['passed'] else 'FAILED'}]")
    lines.append("Figure 2 (cubic H, h = 0.5 on [0, 10000]): max |H−H0| overall / first tenth / last tenth")
    for m, d in c2["drift"].items():
        lines.append(f"  {m:<12} {d['max']:.6e} / {d['first_tenth']:.6e} / {d['last_tenth']:.6e}  "
                     f"ratio {d['ratio']:.6f}  [{'bounded' if d['bounded'] else 'DRIFT'}]")
    if "kahan_largest" in c2:
        lines.append(f"  Kahan's energy error is the largest: {'yes' if c2['kahan_largest'] else 'NO'}")
    if "modified_energy" in c2:
        me = c2["modified_energy"]
        lines.append(f"  Kahan's modified energy H̃ (H̃(y0) = {me['initial']:.15g}): max rel drift "
                     f"{me['max_rel_drift']:.2e} (tol {me['tol']:.0e})  [{'ok' if me['passed'] else 'FAILED'}]")
    return lines


def _jsonable(x):
    if isinstance(x, dict):
        return {k: _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, Path):
        return str(x)
    if hasattr(x, "item"):  # numpy scalars
        return x.item()
    return x


def cmd_figures(args) -> int:
    """Run the ``figures`` subcommand; see the module docstring for the exit status."""
    from .common import dump_json
    from ..plots import write_figures

    if args.out is not None and not str(args.out).strip():
        raise InputError("--out needs a folder name, got ''; leave --out out for the default")
    out = expand_user(args.out, "--out") if args.out else _default_out()
    t0 = time.perf_counter()
    res = write_figures(out, args.format)
    seconds = time.perf_counter() - t0
    c = res["checks"]
    ok = bool(c["figure1"]["passed"] and c["figure2"]["passed"])
    if args.json:
        print(dump_json(_jsonable({"ok": ok, "files": res["files"], "checks": c, "seconds": seconds})))
    else:
        for f in res["files"]:
            print(f"wrote {f}")
        for line in _summary(c):
            print(line)
        print(f"caption checks {'passed' if ok else 'FAILED'} ({seconds:.1f} s)")
    return 0 if ok else 1


def add_parser(sub) -> None:
    """Register the ``figures`` subcommand on ``sub`` (an argparse subparsers object)."""
    p = sub.add_parser("figures", help="reproduce and check the lecture notes' Figures 1 and 2")
    p.add_argument("--out", metavar="DIR", help="output folder (default: the checkout's generated/figures)")
    p.add_argument("--format", choices=("png", "svg", "pdf"), default="png", help="image format (default png)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=cmd_figures)
