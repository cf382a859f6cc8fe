"""Certificates and the verification report (plain data plus renderers).

A :class:`Certificate` records one claim: what was claimed, the expression that
was reduced, the verdict, how it was reached and how long it took.  A
:class:`Report` is the list of certificates for one scheme; it renders as a
dictionary (JSON), Markdown and LaTeX so it can stand next to a proof.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field

__all__ = ["Certificate", "Report", "PROVED", "REFUTED", "NUMERICAL", "UNDECIDED", "STATUSES",
           "METHOD", "FLOW"]

PROVED = "proved"
REFUTED = "refuted"
NUMERICAL = "numerical"
UNDECIDED = "undecided"   # the reduction raised or ran out of time: neither proof nor refutation
STATUSES = (PROVED, REFUTED, NUMERICAL, UNDECIDED)

#: what a certificate is about: the method's own steps (``L(y1) = L(y0)``), or the exact flow
#: of H (``{L, H} = 0``: a first integral of the ODE, which says nothing about any method)
METHOD = "method"
FLOW = "exact flow"
#: the heading of the exact flow's certificates in every rendering
FLOW_HEADING = "about the exact flow of H (facts of the ODE, not claims about the method)"


@dataclass
class Certificate:
    """The verdict on one claim.

    Attributes
    ----------
    claim : str
        The claim in words.
    status : str
        ``"proved"`` (an identity reduced to exactly 0, no floating point),
        ``"refuted"`` (a counterexample point where it is nonzero),
        ``"numerical"`` (checked at sample points with a tolerance; never a proof) or
        ``"undecided"`` (the reduction raised an exception or exceeded its time
        budget; ``details["reason"]`` says which — not a failure, not a proof).
    expression : str
        The expression that was reduced (or checked), as text.
    latex : str
        The same expression in LaTeX.
    method : str
        The reduction that succeeded (``"cancel"``, ``"expand"``, ``"polynomial
        reduction"``...) or how the numerical check was made.
    seconds : float
        Wall time spent on this certificate.
    ref : str
        Where the claim comes from (exercise / section / paper).
    details : dict
        Counterexample, tolerance, sample points, notes; JSON-serialisable.
    subject : str
        :data:`METHOD` (a property of the method's steps, e.g. ``L(y1) = L(y0)``) or
        :data:`FLOW` (a property of the exact flow of H, e.g. ``{L, H} = 0``): reports list
        the two apart, so a first integral of H is never read as the method's proof.
    """

    claim: str
    status: str
    expression: str = ""
    latex: str = ""
    method: str = ""
    seconds: float = 0.0
    ref: str = ""
    details: dict = field(default_factory=dict)
    subject: str = METHOD

    def __post_init__(self):
        if self.status not in STATUSES:
            raise ValueError(f"status must be one of {STATUSES}, got {self.status!r}")
        if self.subject not in (METHOD, FLOW):
            raise ValueError(f"subject must be {METHOD!r} or {FLOW!r}, got {self.subject!r}")

    @property
    def passed(self) -> bool:
        """False for a refutation or a numerical check that failed its tolerance.

        An undecided claim has not failed: ``passed`` is True (see
        :attr:`Report.decided`).
        """
        if self.status == REFUTED:
            return False
        if self.status == UNDECIDED:
            return True
        return bool(self.details.get("passed", True))

    def to_dict(self) -> dict:
        return {"claim": self.claim, "status": self.status, "subject": self.subject,
                "seconds": round(self.seconds, 4), "method": self.method, "ref": self.ref,
                "expression": self.expression, "latex": self.latex, "details": self.details}


def _reason(c: Certificate) -> str:
    return str(c.details.get("reason", "not decided")).replace("\n", " ")


def _md_escape(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ")


def _tex_escape(text: str) -> str:
    out = text
    for a, b in (("\\", r"\textbackslash{}"), ("&", r"\&"), ("%", r"\%"), ("$", r"\$"),
                 ("#", r"\#"), ("_", r"\_"), ("{", r"\{"), ("}", r"\}")):
        out = out.replace(a, b)
    return out


#: How each verdict reads in the text and Markdown reports.
_HEADLINE = {"ok": "ok", "refuted": "REFUTED", "undecided": "UNDECIDED",
             "nothing verified": "NOTHING VERIFIED (no certificate)"}


@dataclass
class Report:
    """All certificates for one scheme (or one system).

    Attributes
    ----------
    title : str
    certificates : list of Certificate
    method : str
        The verified method's name: ``scheme.key``, i.e. ``method-order<K>-<family>`` for a
        symmetric composition (empty for reports not about one scheme).
    composition : dict or None
        For a composed method: family, order, stages, exact, source, base method,
        coefficients (exact / decimal text) and the float64 values the module uses.
    """

    title: str
    certificates: list[Certificate] = field(default_factory=list)
    method: str = ""
    composition: dict | None = None

    @property
    def verdict(self) -> str:
        """``"refuted"`` (some claim refuted), ``"nothing verified"`` (no certificate at all),
        ``"undecided"`` (some claim not decided: exception or time budget) or ``"ok"``."""
        if self.refuted:
            return "refuted"
        if not self.certificates:
            return "nothing verified"
        return "undecided" if self.undecided else "ok"

    @property
    def refuted(self) -> bool:
        """True iff some applicable claim was refuted."""
        return any(c.status == REFUTED for c in self.certificates)

    @property
    def ok(self) -> bool:
        """True iff something was verified and every claim was decided, none refuted.

        A report without certificates, or with an ``undecided`` one, is not ok (though
        not refuted either): a scheme always has claims, and one not decided is not shown.
        """
        return self.verdict == "ok"

    @property
    def all_passed(self) -> bool:
        """Like :attr:`ok`, but a failed numerical check also counts as a failure."""
        return all(c.passed for c in self.certificates)

    @property
    def undecided(self) -> list[Certificate]:
        """The certificates whose claim could not be decided (exception or time budget)."""
        return [c for c in self.certificates if c.status == UNDECIDED]

    @property
    def decided(self) -> bool:
        """True iff every claim was decided (no ``undecided`` certificate)."""
        return not self.undecided

    @property
    def seconds(self) -> float:
        return sum(c.seconds for c in self.certificates)

    def _summary(self) -> str:
        n = len(self.undecided)
        return f", {n} undecided" if n else ""

    def __getitem__(self, i):
        return self.certificates[i]

    def _sections(self):
        """``[(heading or None, [(number, certificate)])]``: the method's certificates, then
        those about the exact flow (numbered as in :attr:`certificates`)."""
        numbered = list(enumerate(self.certificates, 1))
        own = [(i, c) for i, c in numbered if c.subject != FLOW]
        flow = [(i, c) for i, c in numbered if c.subject == FLOW]
        return [(None, own)] + ([(FLOW_HEADING, flow)] if flow else [])

    def __len__(self):
        return len(self.certificates)

    def find(self, text: str) -> list[Certificate]:
        """Certificates whose claim contains ``text`` (case-insensitive)."""
        return [c for c in self.certificates if text.lower() in c.claim.lower()]

    def to_dict(self) -> dict:
        out = {"ok": self.ok, "verdict": self.verdict, "title": self.title, "seconds": round(self.seconds, 3)}
        if self.method:
            out["method"] = self.method
        if self.composition is not None:
            out["composition"] = self.composition
        out["certificates"] = [c.to_dict() for c in self.certificates]
        return out

    def _composed_line(self) -> str:
        """One line naming the composition (empty for a base method)."""
        c = self.composition
        if not c or "family" not in c:
            return ""
        if "kicks" in c:
            return (f"{self.method}: symmetric splitting of T + U, order {c['order']}"
                    f"{' for RKN problems' if c.get('rkn') else ''} ({c['family']}, {c['stages']} "
                    "stages); certificates prefixed 'base step Φ_h' concern the Störmer–Verlet step")
        return (f"{self.method}: {c['base_method']} composed symmetrically to order {c['order']} "
                f"({c['family']}, {c['stages']} stages); certificates prefixed 'base step Φ_h' concern "
                "the base step")

    def to_json(self, **kwargs) -> str:
        return json.dumps(self.to_dict(), **kwargs)

    def markdown(self) -> str:
        """A Markdown section: a summary table, then one paragraph per certificate."""
        lines = [f"### Verification: {_md_escape(self.title)}", "",
                 f"Overall: **{_HEADLINE[self.verdict]}** "
                 f"({len(self.certificates)} claims{self._summary()}, {self.seconds:.2f} s)", ""]
        if self._composed_line():
            lines += [_md_escape(self._composed_line()), ""]
        for heading, certs in self._sections():
            if heading:
                lines += [f"*{heading[0].upper() + heading[1:]}:*", ""]
            if not certs:
                continue
            lines += ["| # | claim | status | method | s |", "|---|---|---|---|---|"]
            for i, c in certs:
                how = _reason(c) if c.status == UNDECIDED else c.method
                lines.append(f"| {i} | {_md_escape(c.claim)} | **{c.status}** | {_md_escape(how)} "
                             f"| {c.seconds:.2f} |")
            lines.append("")
        for i, c in [ic for _, certs in self._sections() for ic in certs]:
            if c.status == UNDECIDED:
                lines.append(f"{i}. *{_md_escape(c.claim)}* ({c.ref}) — **{c.status}**: "
                             f"{_md_escape(_reason(c))}.")
                continue
            lines.append(f"{i}. *{_md_escape(c.claim)}* ({c.ref}) — **{c.status}** by {c.method}.")
            if c.latex:
                lines.append(f"   Reduced: $${c.latex}$$")
            for k, v in c.details.items():
                lines.append(f"   - {k}: {_md_escape(str(v))}")
        return "\n".join(lines) + "\n"

    def _repr_markdown_(self) -> str:
        """The report in a notebook: :meth:`markdown` (Jupyter renders it, formulas by MathJax)."""
        return self.markdown()

    def latex(self) -> str:
        """A LaTeX fragment (``description`` list) for a course handout."""
        out = [rf"\subsection*{{Verification: {_tex_escape(self.title)}}}"]
        if self._composed_line():
            out.append(_tex_escape(self._composed_line()))
        out.append(r"\begin{description}")
        for heading, certs in self._sections():
            if heading:
                out += [r"\end{description}", rf"\paragraph{{{_tex_escape(heading[0].upper() + heading[1:])}}}",
                        r"\begin{description}"]
            out += self._latex_items([c for _, c in certs])
        out.append(r"\end{description}")
        return "\n".join(out) + "\n"

    @staticmethod
    def _latex_items(certs) -> list:
        out = []
        for c in certs:
            if c.status == UNDECIDED:
                out.append(rf"\item[{_tex_escape(c.status)}] {_tex_escape(c.claim)} "
                           rf"({_tex_escape(c.ref)}; {_tex_escape(_reason(c))}, {c.seconds:.2f}\,s)")
                continue
            out.append(rf"\item[{_tex_escape(c.status)}] {_tex_escape(c.claim)} "
                       rf"({_tex_escape(c.ref)}; {_tex_escape(c.method)}, {c.seconds:.2f}\,s)")
            if c.latex:
                out.append(rf"\[ {c.latex} \]")
            for k, v in c.details.items():
                out.append(rf"\\ \emph{{{_tex_escape(k)}}}: {_tex_escape(str(v))}")
        return out

    def __str__(self) -> str:
        rows = [f"{self.title}: {_HEADLINE[self.verdict]}"
                + (f" ({len(self.undecided)} undecided)" if self.undecided else "")]
        if self._composed_line():
            rows.append(f"  {self._composed_line()}")
        for heading, certs in self._sections():
            if heading and certs:
                rows.append(f"  {heading}:")
            rows += self._text_rows([c for _, c in certs])
        return "\n".join(rows)

    @staticmethod
    def _text_rows(certs) -> list:
        rows = []
        for c in certs:
            if c.status == UNDECIDED:
                rows.append(f"  [{c.status:>9}] {c.claim}  ({_reason(c)})")
                continue
            rows.append(f"  [{c.status:>9}] {c.claim}  ({c.method}, {c.seconds:.2f} s)")
            if c.status == REFUTED and "counterexample" in c.details:
                rows.append(f"              counterexample: {c.details['counterexample']}")
        return rows
