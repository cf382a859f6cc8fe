"""methodgen.cite: BibTeX for methodgen and the methods a module uses."""

from __future__ import annotations

import re

import pytest

import methodgen as mg
from methodgen.app.cite import BIBTEX, KEYS_OF, cite
from methodgen.symbolic.compositions import ALL_FAMILIES
from methodgen.codegen.emit import load_module
from methodgen.errors import InputError
from methodgen.symbolic.schemes import METHODS

from conftest import ROOT

GEN = ROOT / "generated"


def _keys(text):
    return re.findall(r"@\w+\{([\w-]+),", text)


def test_every_method_and_family_has_references():
    assert set(METHODS) <= set(KEYS_OF)
    assert set(ALL_FAMILIES) <= set(KEYS_OF)
    assert all(k in BIBTEX for keys in KEYS_OF.values() for k in keys)


@pytest.mark.parametrize("key", sorted(BIBTEX))
def test_entries_are_well_formed(key):
    entry = BIBTEX[key]
    assert _keys(entry) == [key]
    assert entry.count("{") == entry.count("}")
    for field in ("author", "title", "year"):
        assert re.search(rf"^\s+{field} = \{{.+\}},?$", entry, re.M), (key, field)


@pytest.mark.parametrize("name, want", [
    ("kepler_energy_momentum.py", ["methodgen", "labudde1974", "simo1992", "gonzalez1996", "kahan1965"]),
    ("kepler_logh_log_stormer_verlet.py", ["methodgen", "verlet1967", "hairer2003", "mikkola1999", "preto1999",
                                           "kahan1965"]),
    ("rigid_body_avf.py", ["methodgen", "quispel2008", "mqr1999", "kahan1965"]),
    ("pendulum_rattle.py", ["methodgen", "andersen1983", "kahan1965"]),
])
def test_a_module_cites_what_it_uses(name, want):
    mod = load_module(GEN / name)
    assert _keys(cite(mod)) == want
    assert cite(mod) == cite(mod)                      # deterministic


def test_a_composed_scheme_cites_its_family():
    s = mg.discretize(mg.load_scene("kepler").system, "stormer-verlet", order=6, composition="blanes-moan")
    assert _keys(cite(s)) == ["methodgen", "verlet1967", "hairer2003", "blanes2002"]
    assert _keys(cite("avf", "gonzalez", "avf")) == ["methodgen", "quispel2008", "gonzalez1996"]


def test_negative_control_an_unknown_name_is_refused():
    with pytest.raises(InputError, match="known names: .*avf"):
        cite("runge-kutta-4")
    with pytest.raises(InputError, match="generated module, a Scheme or names"):
        cite(3.0)
