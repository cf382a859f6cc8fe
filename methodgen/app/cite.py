"""What to cite for a generated module: methodgen and the methods the module uses, as BibTeX.

:func:`cite` reads a generated module's provenance (``METHOD``, ``COMPOSITION``,
``TIME_TRANSFORM``, a Poisson structure) -- or a :class:`~methodgen.symbolic.schemes.base.Scheme`, or
names -- and returns the BibTeX entries of methodgen and of every method, composition family
and transformation in it, each once, in a fixed order.  This module imports the standard
library only.
"""

from __future__ import annotations

from .._version import __version__
from ..errors import InputError

__all__ = ["cite", "BIBTEX", "KEYS_OF"]

#: BibTeX entries by key.
BIBTEX = {
    "methodgen": f"""@software{{methodgen,
  author = {{{{The methodgen developers}}}},
  title = {{methodgen: geometric numerical integrators generated from a {{H}}amiltonian, with exact proofs of their properties}},
  version = {{{__version__}}},
  year = {{2026}}
}}""",
    "hlw2006": """@book{hlw2006,
  author = {Hairer, E. and Lubich, C. and Wanner, G.},
  title = {Geometric Numerical Integration: Structure-Preserving Algorithms for Ordinary Differential Equations},
  edition = {2},
  publisher = {Springer},
  address = {Berlin},
  year = {2006}
}""",
    "labudde1974": """@article{labudde1974,
  author = {LaBudde, R. A. and Greenspan, D.},
  title = {Discrete mechanics---a general treatment},
  journal = {J. Comput. Phys.},
  volume = {15},
  pages = {134--167},
  year = {1974}
}""",
    "simo1992": """@article{simo1992,
  author = {Simo, J. C. and Tarnow, N.},
  title = {The discrete energy-momentum method. {C}onserving algorithms for nonlinear elastodynamics},
  journal = {Z. Angew. Math. Phys.},
  volume = {43},
  pages = {757--792},
  year = {1992}
}""",
    "gonzalez1996": """@article{gonzalez1996,
  author = {Gonzalez, O.},
  title = {Time integration and discrete {H}amiltonian systems},
  journal = {J. Nonlinear Sci.},
  volume = {6},
  pages = {449--467},
  year = {1996}
}""",
    "quispel2008": """@article{quispel2008,
  author = {Quispel, G. R. W. and McLaren, D. I.},
  title = {A new class of energy-preserving numerical integration methods},
  journal = {J. Phys. A},
  volume = {41},
  number = {4},
  pages = {045206},
  year = {2008}
}""",
    "itoh1988": """@article{itoh1988,
  author = {Itoh, T. and Abe, K.},
  title = {{H}amiltonian-conserving discrete canonical equations based on variational difference quotients},
  journal = {J. Comput. Phys.},
  volume = {76},
  pages = {85--102},
  year = {1988}
}""",
    "kahan1997": """@article{kahan1997,
  author = {Kahan, W. and Li, R.-C.},
  title = {Unconventional schemes for a class of ordinary differential equations---with applications to the {K}orteweg--de {V}ries equation},
  journal = {J. Comput. Phys.},
  volume = {134},
  pages = {316--331},
  year = {1997}
}""",
    "celledoni2013": """@article{celledoni2013,
  author = {Celledoni, E. and McLachlan, R. I. and Owren, B. and Quispel, G. R. W.},
  title = {Geometric properties of {K}ahan's method},
  journal = {J. Phys. A},
  volume = {46},
  number = {2},
  pages = {025201},
  year = {2013}
}""",
    "verlet1967": """@article{verlet1967,
  author = {Verlet, L.},
  title = {Computer ``experiments'' on classical fluids. {I}. {T}hermodynamical properties of {L}ennard-{J}ones molecules},
  journal = {Phys. Rev.},
  volume = {159},
  pages = {98--103},
  year = {1967}
}""",
    "hairer2003": """@article{hairer2003,
  author = {Hairer, E. and Lubich, C. and Wanner, G.},
  title = {Geometric numerical integration illustrated by the {S}t{\\"o}rmer--{V}erlet method},
  journal = {Acta Numer.},
  volume = {12},
  pages = {399--450},
  year = {2003}
}""",
    "andersen1983": """@article{andersen1983,
  author = {Andersen, H. C.},
  title = {Rattle: a ``velocity'' version of the {S}hake algorithm for molecular dynamics calculations},
  journal = {J. Comput. Phys.},
  volume = {52},
  pages = {24--34},
  year = {1983}
}""",
    "ryckaert1977": """@article{ryckaert1977,
  author = {Ryckaert, J.-P. and Ciccotti, G. and Berendsen, H. J. C.},
  title = {Numerical integration of the cartesian equations of motion of a system with constraints: molecular dynamics of n-alkanes},
  journal = {J. Comput. Phys.},
  volume = {23},
  pages = {327--341},
  year = {1977}
}""",
    "butcher1964": """@article{butcher1964,
  author = {Butcher, J. C.},
  title = {Implicit {R}unge--{K}utta processes},
  journal = {Math. Comp.},
  volume = {18},
  pages = {50--64},
  year = {1964}
}""",
    "hairer2010": """@article{hairer2010,
  author = {Hairer, E.},
  title = {Energy-preserving variant of collocation methods},
  journal = {JNAIAM J. Numer. Anal. Ind. Appl. Math.},
  volume = {5},
  pages = {73--84},
  year = {2010}
}""",
    "hairer2000": """@article{hairer2000,
  author = {Hairer, E.},
  title = {Symmetric projection methods for differential equations on manifolds},
  journal = {BIT},
  volume = {40},
  pages = {726--734},
  year = {2000}
}""",
    "yoshida1990": """@article{yoshida1990,
  author = {Yoshida, H.},
  title = {Construction of higher order symplectic integrators},
  journal = {Phys. Lett. A},
  volume = {150},
  pages = {262--268},
  year = {1990}
}""",
    "suzuki1990": """@article{suzuki1990,
  author = {Suzuki, M.},
  title = {Fractal decomposition of exponential operators with applications to many-body theories and {M}onte {C}arlo simulations},
  journal = {Phys. Lett. A},
  volume = {146},
  pages = {319--323},
  year = {1990}
}""",
    "kahanli1997": """@article{kahanli1997,
  author = {Kahan, W. and Li, R.-C.},
  title = {Composition constants for raising the orders of unconventional schemes for ordinary differential equations},
  journal = {Math. Comp.},
  volume = {66},
  pages = {1089--1099},
  year = {1997}
}""",
    "mclachlan1995": """@article{mclachlan1995,
  author = {McLachlan, R. I.},
  title = {On the numerical integration of ordinary differential equations by symmetric composition methods},
  journal = {SIAM J. Sci. Comput.},
  volume = {16},
  pages = {151--168},
  year = {1995}
}""",
    "sofroniou2005": """@article{sofroniou2005,
  author = {Sofroniou, M. and Spaletta, G.},
  title = {Derivation of symmetric composition constants for symmetric integrators},
  journal = {Optim. Methods Softw.},
  volume = {20},
  pages = {597--613},
  year = {2005}
}""",
    "blanes2002": """@article{blanes2002,
  author = {Blanes, S. and Moan, P. C.},
  title = {Practical symplectic partitioned {R}unge--{K}utta and {R}unge--{K}utta--{N}ystr{\\"o}m methods},
  journal = {J. Comput. Appl. Math.},
  volume = {142},
  pages = {313--330},
  year = {2002}
}""",
    "blanes2006": """@article{blanes2006,
  author = {Blanes, S. and Casas, F. and Murua, A.},
  title = {Composition methods for differential equations with processing},
  journal = {SIAM J. Sci. Comput.},
  volume = {27},
  pages = {1817--1843},
  year = {2006}
}""",
    "hairer1997": """@article{hairer1997,
  author = {Hairer, E.},
  title = {Variable time step integration with symplectic methods},
  journal = {Appl. Numer. Math.},
  volume = {25},
  pages = {219--227},
  year = {1997}
}""",
    "mikkola1999": """@article{mikkola1999,
  author = {Mikkola, S. and Tanikawa, K.},
  title = {Explicit symplectic algorithms for time-transformed {H}amiltonians},
  journal = {Celest. Mech. Dyn. Astron.},
  volume = {74},
  pages = {287--295},
  year = {1999}
}""",
    "preto1999": """@article{preto1999,
  author = {Preto, M. and Tremaine, S.},
  title = {A class of symplectic integrators with adaptive time step for separable {H}amiltonian systems},
  journal = {Astron. J.},
  volume = {118},
  pages = {2532--2541},
  year = {1999}
}""",
    "mqr1999": """@article{mqr1999,
  author = {McLachlan, R. I. and Quispel, G. R. W. and Robidoux, N.},
  title = {Geometric integration using discrete gradients},
  journal = {Philos. Trans. R. Soc. Lond. A},
  volume = {357},
  pages = {1021--1045},
  year = {1999}
}""",
    "wisdom1991": """@article{wisdom1991,
  author = {Wisdom, J. and Holman, M.},
  title = {Symplectic maps for the {N}-body problem},
  journal = {Astron. J.},
  volume = {102},
  pages = {1528--1538},
  year = {1991}
}""",
    "laskar2001": """@article{laskar2001,
  author = {Laskar, J. and Robutel, P.},
  title = {High order symplectic integrators for perturbed {H}amiltonian systems},
  journal = {Celest. Mech. Dyn. Astron.},
  volume = {80},
  pages = {39--62},
  year = {2001}
}""",
    "kahan1965": """@article{kahan1965,
  author = {Kahan, W.},
  title = {Further remarks on reducing truncation errors},
  journal = {Commun. ACM},
  volume = {8},
  number = {1},
  pages = {40},
  year = {1965}
}""",
}

#: What each name cites: the methods (``methodgen methods``), the composition families, the
#: time transformations ("poincare", "log"), "poisson" (discrete gradients of y' = S(y)∇H),
#: "wisdom-holman" and "compensated" (the compensated summation every generated loop uses).
KEYS_OF = {
    "midpoint": ("hlw2006",),
    "trapezoidal": ("hlw2006",),
    "energy-momentum": ("labudde1974", "simo1992", "gonzalez1996"),
    "avf": ("quispel2008",),
    "gonzalez": ("gonzalez1996",),
    "itoh-abe": ("itoh1988",),
    "kahan": ("kahan1997", "celledoni2013"),
    "stormer-verlet": ("verlet1967", "hairer2003"),
    "stormer-verlet-projected": ("verlet1967", "hairer2000"),
    "rattle": ("andersen1983",),
    "shake": ("ryckaert1977",),
    "gauss": ("butcher1964", "hlw2006"),
    "energy-collocation": ("hairer2010",),
    "triple-jump": ("yoshida1990", "suzuki1990"),
    "suzuki": ("suzuki1990",),
    "kahan-li": ("kahanli1997",),
    "mclachlan": ("mclachlan1995",),
    "sofroniou-spaletta": ("sofroniou2005",),
    "blanes-moan": ("blanes2002",),
    "blanes-moan-rkn": ("blanes2002",),
    "blanes-casas-murua": ("blanes2006",),
    "poincare": ("hairer1997",),
    "log": ("mikkola1999", "preto1999"),
    "poisson": ("mqr1999",),
    "wisdom-holman": ("wisdom1991", "laskar2001"),
    "compensated": ("kahan1965",),
}


def _names_of(obj) -> list[str]:
    """The names :data:`KEYS_OF` knows that ``obj`` uses: a generated module, a Scheme, a
    name, or a list of those."""
    if isinstance(obj, str):
        return [obj]
    if isinstance(obj, (list, tuple)):
        return [n for o in obj for n in _names_of(o)]
    method = getattr(obj, "METHOD", None) or getattr(obj, "method", None)
    if not isinstance(method, str):
        raise InputError(f"cite takes a generated module, a Scheme or names; got a {type(obj).__name__}")
    names = [method]
    comp = getattr(obj, "COMPOSITION", None)
    if comp is None:
        comp = getattr(obj, "composition", None)
    family = comp.get("family") if isinstance(comp, dict) else getattr(comp, "family", None)
    if isinstance(family, str):
        names.append(family)
    tt = getattr(obj, "TIME_TRANSFORM", None)
    if isinstance(tt, dict):
        names.append("log" if tt.get("form") == "log" else "poincare")
    system = getattr(obj, "system", None)
    if getattr(obj, "STRUCTURE_MATRIX", None) is not None or type(system).__name__ == "PoissonSystem":
        names.append("poisson")
    if hasattr(obj, "METHOD"):
        names.append("compensated")   # a generated module's loop sums compensated
    return names


def cite(*objs) -> str:
    """BibTeX of methodgen and of what ``objs`` use, each entry once.

    Parameters
    ----------
    *objs : module, Scheme or str
        Generated modules (their ``METHOD``, ``COMPOSITION``, ``TIME_TRANSFORM`` and Poisson
        structure), :class:`~methodgen.symbolic.schemes.base.Scheme` objects, or names of
        :data:`KEYS_OF` (a method, a composition family, ``"poincare"``, ``"log"``,
        ``"poisson"``, ``"wisdom-holman"``, ``"compensated"``).

    Returns
    -------
    str
        BibTeX entries separated by blank lines: methodgen first, then the methods' in the order
        first named.

    Raises
    ------
    InputError
        A name that is not one of :data:`KEYS_OF` (the message lists them).

    Examples
    --------
    >>> print(cite("avf").split("\\n")[0])
    @software{methodgen,
    """
    keys = ["methodgen"]
    for name in _names_of(list(objs)):
        got = KEYS_OF.get(name)
        if got is None:
            raise InputError(f"cite: no references for {name!r}; known names: {', '.join(sorted(KEYS_OF))}")
        keys += [k for k in got if k not in keys]
    return "\n\n".join(BIBTEX[k] for k in keys) + "\n"
