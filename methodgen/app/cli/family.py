"""``methodgen run`` and ``methodgen verify`` of a family of symbolic size: what a lattice scene
(:mod:`methodgen.app.cli.lattice`) and a particle scene (:mod:`methodgen.app.cli.particles`) share --
a run whose step failure is one line and a non-zero exit, its report, and the certificates."""

from __future__ import annotations

import sys

from .common import EXIT_NUMERICAL, dump_json, section_lines

#: the generated modules' step failures: reported as one line, never as a traceback
_STEP_FAILURES = ("ConvergenceError", "NonFiniteError", "ResolutionError")


def run_and_report(args, scene_name: str, run, header, work) -> int:
    """Run ``run()`` (a scene's report dict) and print it: ``--json`` as one object, else the
    ``header`` line, the invariants' table and the time (``work(rep)``: what the steps cost besides
    time, e.g. ", 3.00 Newton iterations").  A module's step failure: one line on stderr (and a
    JSON object with ``success`` false), exit status :data:`EXIT_NUMERICAL`.  ``header(rep)``: the
    first line."""
    try:
        rep = run()
    except Exception as exc:     # the module's ConvergenceError / NonFiniteError / ResolutionError
        if type(exc).__name__ not in _STEP_FAILURES:
            raise
        print(f"methodgen: stopped: {exc}", file=sys.stderr)
        if args.json:
            print(dump_json({"scene": scene_name, "success": False, "message": str(exc)}))
        return EXIT_NUMERICAL
    if args.json:
        print(dump_json(rep))
        return 0
    if "section" in rep:
        print("\n".join(section_lines(rep)))
        return 0
    print(header(rep))
    print(f"{'invariant':>10} {'initial':>24} {'final':>24} {'max abs error':>14}")
    for k, v in rep["invariants"].items():
        print(f"{k:>10} {v['initial']:>24.17g} {v['final']:>24.17g} {v['max_abs_error']:>14.3e}")
    print(f"build {rep['build_seconds']:.2f} s; {rep['seconds']:.2f} s for the steps "
          f"({rep['seconds_per_step'] * 1e3:.3g} ms a step{work(rep)})")
    return 0


def verify_and_report(args, scene_name: str, methods, certify, title: str, every: str) -> int:
    """Print the certificates of each of ``methods`` (``certify(method)`` → (certificates, the
    invariants they prove kept)): ``--json`` as one object, else ``title`` and a line a certificate
    and a line a method (what it keeps at every ``every``).  Exit 0 when every one is proved."""
    out, ok, kept = [], True, {}
    for m in methods:
        certs, kept[m] = certify(m)
        for c in certs:
            out.append({"method": m, "claim": c.claim, "status": c.status, "how": c.method})
            ok &= c.status == "proved"
    if getattr(args, "json", False):
        print(dump_json({"scene": scene_name, "certificates": out, "all_proved": ok, "proved_invariants": kept}))
    else:
        print(title)
        for c in out:
            print(f"  [{c['status']}] {c['method']}: {c['claim']} ({c['how']})")
        for m, names in kept.items():
            print(f"  {m} keeps, proved at every {every}: {', '.join(names) if names else 'nothing'}")
    return 0 if ok else EXIT_NUMERICAL
