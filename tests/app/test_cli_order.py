"""High order on the command line and in scenes: ``--order K``, ``--composition F``, ``[run] order``
(issue 14, item 1, user-facing part)."""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pytest

import methodgen as mg
from methodgen.app import cli
from methodgen.app.cli import generate as cli_generate
from methodgen.codegen.emit import load_module
from methodgen.errors import SceneError

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module", autouse=True)
def cache(tmp_path_factory):
    """A private module cache: composed modules of built-in scenes go there, not to generated/."""
    root = tmp_path_factory.mktemp("order") / "cache"
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("METHODGEN_CACHE", str(root))
        yield root


def _main(capsys, *argv):
    code = cli.main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def _run_json(capsys, *argv):
    code, out, err = _main(capsys, "run", *argv, "--json")
    assert code == 0, err
    return json.loads(out)


def _period_error(capsys, order: int, n: int) -> tuple[float, dict]:
    """Kepler (e = 0.6, period 2π) over one period in ``n`` steps: the exact solution is y0 again."""
    rep = _run_json(capsys, "kepler", "--order", str(order), "--h", repr(2 * math.pi / n), "--steps", str(n))
    return float(np.max(np.abs(np.array(rep["y_final"]) - np.array(rep["y0"])))), rep


def test_order_4_and_8_use_their_modules_and_are_more_accurate(capsys, cache):
    errors = {}
    for order in (2, 4, 8):
        for n in (100, 200):
            errors[order, n], rep = _period_error(capsys, order, n)
            module = load_module(rep["module"])
            assert rep["order"] == module.ORDER == order
            if order == 2:
                assert rep["composition"] is None and module.COMPOSITION is None
                assert Path(rep["module"]).parent == ROOT / "generated"
            else:
                family = {4: "suzuki", 8: "kahan-li"}[order]          # the documented defaults
                assert rep["composition"] == module.COMPOSITION == {"family": family, "order": order,
                                                                    "stages": len(module.GAMMAS)}
                # Not committed: a composed module of a built-in scene lives in the cache.
                assert Path(rep["module"]).parent == cache
            # What the base method keeps is kept at every order: H and q × p to round-off.
            for name in ("H", "Lx", "Ly", "Lz"):
                assert rep["invariants"][name]["max_abs_error"] < 1e-14, (order, name)
    # Physics, not timing: against the exact solution at the same h, higher order is better …
    for n in (100, 200):
        assert errors[4, n] < 1e-2 * errors[2, n] and errors[8, n] < 1e-4 * errors[4, n]   # measured 1e-3, 3e-6
    # … and the error falls with h like h^order (measured 2.0, 4.0, 8.2).
    for order in (2, 4, 8):
        observed = math.log2(errors[order, 100] / errors[order, 200])
        assert abs(observed - order) < 0.5, (order, observed)


def test_text_report_names_order_and_composition(capsys):
    code, out, err = _main(capsys, "run", "kepler", "--order", "4", "--steps", "5")
    assert code == 0, err
    assert "order 4 (suzuki composition, 5 stages)" in out.splitlines()[0]
    code, out, err = _main(capsys, "run", "kepler", "--order", "6", "--composition", "triple-jump",
                           "--steps", "5")
    assert code == 0, err
    assert "order 6 (triple-jump composition, 9 stages)" in out
    code, out, err = _main(capsys, "run", "kepler", "--steps", "5")
    assert code == 0 and " order 2 " in out.splitlines()[0] and "composition" not in out


# --- scenes ------------------------------------------------------------------------------

DUFFING = """name = "duffing"
[system]
H = "p**2/2 + q**4/4 - q**2/2"
q = ["q"]
p = ["p"]
[run]
method = "{method}"
h = 0.05
steps = 20
y0 = [0.1, 0.5]
"""


def _scene(tmp_path, extra: str, method: str = "energy-momentum", name: str = "s.toml") -> Path:
    f = tmp_path / name
    f.write_text(DUFFING.format(method=method) + extra + "\n")
    return f


def test_scene_order_is_parsed_and_overridden(tmp_path, capsys):
    plain = mg.load_scene(_scene(tmp_path, "", name="plain.toml"))
    assert (plain.order, plain.composition) == (2, None)
    assert (mg.load_scene("kepler").order, mg.load_scene("kepler").composition) == (2, None)
    f = _scene(tmp_path, 'order = 6\ncomposition = "triple-jump"')
    scene = mg.load_scene(f)
    assert (scene.order, scene.composition) == (6, "triple-jump")
    rep = _run_json(capsys, str(f))
    assert rep["order"] == 6 and rep["composition"] == {"family": "triple-jump", "order": 6, "stages": 9}
    assert load_module(rep["module"]).ORDER == 6
    # --composition keeps the scene's order; --order alone takes that order's default family.
    rep = _run_json(capsys, str(f), "--composition", "suzuki")
    assert rep["composition"] == {"family": "suzuki", "order": 6, "stages": 25}
    rep = _run_json(capsys, str(f), "--order", "8")
    assert rep["composition"]["family"] == "kahan-li" and rep["order"] == 8
    rep = _run_json(capsys, str(f), "--order", "2")
    assert rep["order"] == 2 and rep["composition"] is None


def test_sweep_builds_the_scenes_order(tmp_path):
    from methodgen.app.sweep import load_spec, plan_sweep

    _scene(tmp_path, "order = 4", name="s4.toml")
    spec = tmp_path / "sweep.toml"
    spec.write_text('scene = "s4.toml"\nh = 0.05\nsteps = 4\n')
    plan = plan_sweep(load_spec(spec))
    module = load_module(plan.modules["energy-momentum"].path)
    assert module.ORDER == 4 and module.COMPOSITION["family"] == "suzuki"


VALID_ORDERS = "2, 4, 6, 8, 10"
FAMILIES = "triple-jump (orders 4, 6, 8, 10), suzuki (orders 4, 6, 8, 10), kahan-li (orders 6, 8)"


@pytest.mark.parametrize("extra, fragments", [
    ("order = 3", ["[run].order must be one of " + VALID_ORDERS, "got 3"]),
    ("order = 4.0", ["[run].order must be one of " + VALID_ORDERS, "got 4.0"]),
    ('order = "8"', ["[run].order must be one of " + VALID_ORDERS, "got '8'"]),
    ('order = 4\ncomposition = "bogus"', ["unknown composition family 'bogus'", FAMILIES]),
    ('composition = "suzuki"', ["[run].composition = 'suzuki' needs [run].order above 2",
                                "orders 4, 6, 8, 10"]),
    ('order = 4\ncomposition = "kahan-li"', ["the kahan-li family has orders 6, 8, not 4",
                                             "families with order 4: triple-jump, suzuki"]),
])
def test_bad_scene_order_is_refused_at_load(tmp_path, capsys, extra, fragments):
    f = _scene(tmp_path, extra)
    with pytest.raises(SceneError) as info:
        mg.load_scene(f)
    for frag in fragments:
        assert frag in str(info.value)
    code, out, err = _main(capsys, "run", str(f))
    assert code == cli.EXIT_INPUT and not out
    assert all(frag in err for frag in fragments)
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1


def test_non_symmetric_method_in_a_scene_is_refused_at_run(tmp_path, capsys):
    kepler = (ROOT / "methodgen" / "symbolic" / "scenes" / "kepler.toml").read_text()
    f = tmp_path / "k.toml"
    f.write_text(kepler.replace('method = ["energy-momentum", "midpoint"]', 'method = "itoh-abe"\norder = 4'))
    assert mg.load_scene(f).order == 4
    code, out, err = _main(capsys, "run", str(f), "--steps", "2")
    assert code == cli.EXIT_INPUT and not out
    assert "itoh-abe is not symmetric" in err and "Symmetric methods that apply: midpoint, energy-momentum" in err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1


# --- command-line errors --------------------------------------------------------------

BAD = [
    (["--order", "3"], ["--order must be one of " + VALID_ORDERS, "got 3"]),
    (["--order", "four"], ["--order must be one of " + VALID_ORDERS, "got 'four'"]),
    (["--order", "4", "--composition", "bogus"], ["--composition: unknown composition family 'bogus'", FAMILIES]),
    (["--composition", "suzuki"], ["--composition = 'suzuki' needs --order above 2", "orders 4, 6, 8, 10"]),
    (["--order", "4", "--composition", "kahan-li"], ["the kahan-li family has orders 6, 8, not 4",
                                                     "families with order 4: triple-jump, suzuki"]),
    (["--method", "itoh-abe", "--order", "4"], ["order 4 is built by symmetric composition",
                                                "itoh-abe is not symmetric",
                                                "Symmetric methods that apply: midpoint, energy-momentum"]),
]


@pytest.mark.parametrize("argv, fragments", BAD)
def test_bad_order_on_run_is_a_one_line_error(capsys, argv, fragments):
    code, out, err = _main(capsys, "run", "kepler", "--steps", "2", *argv)
    assert code == cli.EXIT_INPUT and not out
    assert all(frag in err for frag in fragments), err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1


@pytest.mark.parametrize("command", [["verify", "kepler"], ["generate", "kepler", "--check"]])
@pytest.mark.parametrize("argv, fragments", BAD[:5])
def test_bad_order_on_verify_and_generate(capsys, command, argv, fragments):
    code, out, err = _main(capsys, *command, *argv)
    assert code == cli.EXIT_INPUT and not out
    assert all(frag in err for frag in fragments), err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1


def test_verify_takes_the_order(capsys):
    code, out, err = _main(capsys, "verify", "harmonic", "--method", "midpoint", "--order", "4", "--json")
    rep = json.loads(out)
    assert code == 0 and rep["ok"], err
    assert rep["order"] == 4 and rep["composition"] == {"family": "suzuki", "order": 4, "stages": 5}
    code, out, err = _main(capsys, "verify", "kepler", "--method", "itoh-abe", "--order", "4")
    assert code == cli.EXIT_INPUT and "itoh-abe is not symmetric" in err


def test_methods_lists_what_composes(capsys):
    code, out, _ = _main(capsys, "methods", "--json")
    rep = json.loads(out)
    flags = {r["name"]: r["composable"] for r in rep["methods"]}
    assert flags["energy-momentum"] and flags["midpoint"] and flags["rattle"] and not flags["itoh-abe"]
    comp = rep["compositions"]
    assert comp["orders"] == [2, 4, 6, 8, 10] and comp["families"]["kahan-li"] == [6, 8]
    assert comp["default_family"] == {"4": "suzuki", "6": "kahan-li", "8": "kahan-li", "10": "sofroniou-spaletta"}
    code, out, _ = _main(capsys, "methods")
    assert code == 0 and "--order 4/6/8/10" in out and "itoh-abe, gauss, energy-collocation only where symmetric of order 2" in out
    assert "default: order 4 suzuki, order 6 kahan-li, order 8 kahan-li, order 10 sofroniou-spaletta" in out


# --- generate ---------------------------------------------------------------------------

def test_generate_writes_and_checks_composed_modules(tmp_path, capsys, monkeypatch):
    out_dir = tmp_path / "gen"
    out_dir.mkdir()
    composed = ["kepler_energy_momentum_order4_suzuki.py", "kepler_midpoint_order4_suzuki.py"]
    code, out, err = _main(capsys, "generate", "kepler", "--order", "4", "--out", str(out_dir))
    assert code == 0, err
    assert sorted(p.name for p in out_dir.glob("*.py")) == composed
    assert load_module(out_dir / composed[0]).ORDER == 4
    # Without --order: the scene's own modules, and the composed ones present are kept in sync.
    code, out, err = _main(capsys, "generate", "kepler", "--out", str(out_dir), "--json")
    rep = json.loads(out)
    assert code == 0 and sorted(Path(p).name for p in rep["written"]) == ["kepler_energy_momentum.py",
                                                                          "kepler_midpoint.py"]
    assert sorted(Path(p).name for p in rep["unchanged"]) == composed
    code, out, err = _main(capsys, "generate", "kepler", "--out", str(out_dir), "--check")
    assert code == 0 and "(4 modules)" in out, out + err
    target = out_dir / composed[1]
    target.write_text(target.read_text().replace("GAMMAS", "GAMMAS ", 1))
    code, out, err = _main(capsys, "generate", "kepler", "--out", str(out_dir), "--check")
    assert code == 1 and f"{target}: differs" in out

    # A built-in scene whose [run] declares an order: its composed modules are targets too.
    scene = dataclasses.replace(mg.load_scene("harmonic"), methods=("midpoint",), order=4)
    monkeypatch.setattr(cli_generate, "load_scene", lambda name: scene)
    other = tmp_path / "declared"
    other.mkdir()
    code, out, err = _main(capsys, "generate", "harmonic", "--out", str(other))
    assert code == 0, err
    assert sorted(p.name for p in other.glob("*.py")) == ["harmonic_midpoint.py",
                                                          "harmonic_midpoint_order4_suzuki.py"]
    (other / "harmonic_midpoint_order4_suzuki.py").unlink()
    code, out, err = _main(capsys, "generate", "harmonic", "--out", str(other), "--check")
    assert code == 1 and "harmonic_midpoint_order4_suzuki.py: missing" in out
