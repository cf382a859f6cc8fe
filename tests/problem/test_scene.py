"""Scene files: validation with messages that name the key and what is valid."""

from __future__ import annotations

import pytest

import methodgen as mg
from methodgen.errors import MethodNotApplicable, SceneError

GOOD = '''name = "s"
[system]
H = "p**2/2 + k*q**2/2"
q = ["q"]
p = ["p"]
[params]
k = 1.0
[run]
method = "midpoint"
h = 0.1
steps = 10
y0 = [1.0, 0.0]
'''


def write(tmp_path, text):
    f = tmp_path / "scene.toml"
    f.write_text(text)
    return f


def test_good_scene(tmp_path):
    sc = mg.load_scene(write(tmp_path, GOOD))
    assert sc.method == "midpoint" and sc.h == 0.1 and sc.y0 == (1.0, 0.0) and not sc.builtin


@pytest.mark.parametrize("edit, fragment", [
    (lambda t: t.replace('name = "s"', 'name = "s"\ncolour = "red"'), "unknown key(s) ['colour']"),
    (lambda t: t.replace("steps = 10", "steps = 10\nstep = 3"), "unknown key(s) ['step'] in [run]"),
    (lambda t: t.replace("h = 0.1", 'h = "0.1"'), "[run].h must be a number"),
    (lambda t: t.replace("h = 0.1", "h = 0"), "non-zero"),
    (lambda t: t.replace("steps = 10", "steps = -1"), ">= 0"),
    (lambda t: t.replace("y0 = [1.0, 0.0]", "y0 = [1.0]"), "has 1 values"),
    (lambda t: t.replace("y0 = [1.0, 0.0]", "y0 = [1.0, nan]"), "finite"),
    (lambda t: t.replace("k = 1.0", "k = inf"), "finite"),
    (lambda t: t.replace("k = 1.0", "c = 1.0"), "unknown symbol 'k'"),
    (lambda t: t.replace('H = "p**2/2 + k*q**2/2"', 'H = "__import__(\'os\')"'), "unknown function '__import__'"),
    (lambda t: t.replace("[run]", "[run"), "invalid TOML"),
    (lambda t: t.replace('q = ["q"]', "q = [1]"), "list of strings"),
])
def test_bad_scenes(tmp_path, edit, fragment):
    with pytest.raises(SceneError) as err:
        mg.load_scene(write(tmp_path, edit(GOOD)))
    assert fragment in str(err.value)


def test_builtin_scenes_load():
    for name in mg.scenes():
        sc = mg.load_scene(name)
        assert sc.builtin and sc.name == name
        for m in sc.methods:
            assert m in mg.methods()


def test_method_that_does_not_apply_lists_those_that_do():
    nonsep = mg.Hamiltonian("p**2/2 + q**2/2 + q**2*p**2", q=["q"], p=["p"])
    with pytest.raises(MethodNotApplicable) as err:
        mg.discretize(nonsep, "energy-momentum")
    assert "separable" in str(err.value) and "midpoint" in str(err.value)
    coupled = mg.Hamiltonian("(px**2+py**2)/2 + exp(x*y)", q=["x", "y"], p=["px", "py"])
    with pytest.raises(MethodNotApplicable, match="V\\(\\|q\\|\\)"):
        mg.discretize(coupled, "energy-momentum")
    # A sum of one-coordinate terms is fine (term-wise discrete gradient).
    aniso = mg.Hamiltonian("(px**2+py**2)/2 + x**2 + 2*y**2 + x**3", q=["x", "y"], p=["px", "py"])
    assert mg.discretize(aniso, "energy-momentum").traits.energy_preserving
    with pytest.raises(mg.InputError, match="known methods"):
        mg.discretize(nonsep, "rk4")


def test_a_vector_field_without_h_is_out_of_scope(tmp_path):
    """A scene that gives a vector field (the ABC flow) instead of H is refused with the scope:
    Hamiltonian and Poisson systems only, and what to use instead.  Control: an unknown key
    beside H is the usual unknown-key error."""
    from methodgen.errors import SceneError

    path = tmp_path / "abc.toml"
    path.write_text('name = "abc"\ndescription = "ABC flow"\n[system]\n'
                    'f = ["sin(z) + cos(y)", "sin(x) + cos(z)", "sin(y) + cos(x)"]\ny = ["x", "y", "z"]\n'
                    '[run]\ny0 = [0.1, 0.2, 0.3]\n')
    with pytest.raises(SceneError, match="Hamiltonian systems only.*out of scope.*solve_ivp"):
        mg.load_scene(path)
    path.write_text('name = "h"\ndescription = "x"\n[system]\nH = "p**2/2 + q**2/2"\nq = ["q"]\np = ["p"]\n'
                    'f = ["p"]\n[run]\ny0 = [0.1, 0.2]\n')
    with pytest.raises(SceneError, match=r"unknown key\(s\) \['f'\]"):
        mg.load_scene(path)
