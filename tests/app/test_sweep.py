"""Parameter sweeps: spec validation, in-process vs Dask, failures reported never dropped, CLI."""

from __future__ import annotations

import importlib.util
import json
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest

import methodgen.app.sweep as sw
from methodgen.app.cli import main
from methodgen.errors import InputError, MethodgenError

ROOT = Path(__file__).resolve().parents[2]

#: 2 methods × 2 h × 2 k × 2 batches = 16 tasks, about a second in-process.
SMALL = {"scene": "kepler", "methods": ["midpoint", "energy-momentum"], "h": [0.02, 0.01], "steps": 60,
         "params": {"k": [1.0, 1.5]}, "initial": {"count": 6, "spread": 1e-3, "seed": 3, "batch": 3}}

#: The unperturbed y0: one trajectory per task, compared against bench.reference.
WITH_REF = {"scene": "kepler", "methods": ["energy-momentum"], "h": [0.02], "t_final": 0.5,
            "params": {"k": [1.0, 1.5]}}


def _results(rows):
    """Rows without the one field that legitimately differs between runs (CPU time)."""
    return [{k: v for k, v in r.items() if k != "cpu_seconds"} for r in rows]


def _write(tmp_path, text, name="spec.toml"):
    path = tmp_path / name
    path.write_text(text)
    return path


# --- spec validation ----------------------------------------------------------------------

@pytest.mark.parametrize("change, words", [
    ({"colour": "red"}, ["unknown key", "colour", "valid keys"]),
    ({"h": "fast"}, ["h must be a number or a list of numbers", "str"]),
    ({"h": [0.01, "x"]}, ["h[1] must be a number"]),
    ({"h": [0.01, -0.1]}, ["h values must be > 0"]),
    ({"h": [0.01, 0.01]}, ["duplicate"]),
    ({"h": []}, ["empty"]),
    ({"steps": True}, ["steps must be an integer", "bool"]),
    ({"steps": -1}, ["steps must be >= 0"]),
    ({"t_final": 1.0}, ["either steps or t_final"]),
    ({"methods": ["midpoint", "rk4"]}, ["unknown method 'rk4'", "energy-momentum"]),
    ({"methods": []}, ["methods must not be an empty list"]),
    ({"methods": ["midpoint", 3]}, ["methods[1] must be a string"]),
    ({"params": {"mass": [1.0]}}, ["unknown parameter", "mass", "'m', 'k'"]),
    ({"params": {"k": ["1"]}}, ["[params].k[0] must be a number"]),
    ({"params": {"k": [float("inf")]}}, ["must be finite"]),
    ({"initial": {"count": 4, "size": 2}}, ["unknown key", "size", "[initial]", "batch"]),
    ({"initial": {"count": 4, "batch": 0}}, ["batch must be >= 1"]),
    ({"initial": {"count": 4, "spread": -1.0}}, ["spread must be >= 0"]),
    ({"initial": {"count": 2.5}}, ["count must be an integer"]),
    ({"check_resolution": "no"}, ["check_resolution must be a boolean"]),
    ({"scene": "no-such-scene"}, ["no built-in scene or file", "kepler"]),
])
def test_spec_errors_name_the_key(change, words):
    data = {**SMALL, **change}
    with pytest.raises(InputError) as err:
        sw.parse_spec(data)
    for w in words:
        assert w in str(err.value), str(err.value)


def test_spec_missing_scene_and_bad_toml(tmp_path):
    with pytest.raises(sw.SpecError, match="missing key 'scene'"):
        sw.parse_spec({"h": 0.1})
    with pytest.raises(sw.SpecError, match="invalid TOML"):
        sw.load_spec(_write(tmp_path, "scene = kepler\n"))
    with pytest.raises(sw.SpecError, match="cannot read sweep spec"):
        sw.load_spec(tmp_path / "missing.toml")


def test_inapplicable_method_is_an_input_error():
    with pytest.raises(InputError, match="(?i)rattle|constraint"):
        sw.run_sweep({"scene": "kepler", "methods": ["rattle"], "steps": 1})


def test_spec_defaults_scene_path_and_tasks(tmp_path):
    # A scene file next to the spec, referenced relatively; defaults from the scene.
    scene = (ROOT / "methodgen" / "symbolic" / "scenes" / "harmonic.toml").read_text().replace('"harmonic"', '"osc"')
    _write(tmp_path, scene, "osc.toml")
    spec = sw.load_spec(_write(tmp_path, 'scene = "osc.toml"\nh = 0.1\nt_final = 0.42\n'))
    assert spec.scene.name == "osc" and spec.methods == ("midpoint", "energy-momentum")
    plan = sw.plan_sweep(spec)
    assert [t.name for t in plan.tasks] == ["midpoint h=0.1 batch=0", "energy-momentum h=0.1 batch=0"]
    t = plan.tasks[0]
    assert t.steps == 5 and t.h_used == pytest.approx(0.084) and t.y0.shape == (1, 2)   # ceil(4.2) steps


def test_ensemble_is_seeded_and_split_into_batches():
    spec = sw.parse_spec(SMALL)
    plan = sw.plan_sweep(spec)
    assert len(plan.tasks) == 16 and not plan.refs  # perturbed ensemble: no reference
    Y = np.concatenate([t.y0 for t in plan.tasks if t.key[:3] == ("midpoint", 0.02, 1.0)])
    assert Y.shape == (6, 6)
    assert np.array_equal(Y, sw.initial_states(spec))
    assert 0 < np.max(np.abs(Y - np.array(spec.scene.y0))) < 1e-2
    assert np.array_equal(sw.initial_states(sw.parse_spec(SMALL)), Y)  # same seed, same draw


# --- results ------------------------------------------------------------------------------

def test_in_process_rows_sorted_and_measured():
    rep = sw.run_sweep(SMALL)
    rows = rep["rows"]
    assert rep["tasks"] == rep["ok"] == 16 and rep["failed"] == 0
    assert rep["trajectory_steps"] == 2 * 2 * 2 * 6 * 60
    keys = [(r["method"], r["h"], r["params"]["k"], r["batch"]) for r in rows]
    assert keys == sorted(keys)
    for r in rows:
        assert r["status"] == "ok" and r["steps_done"] == 60 and r["trajectories"] == 3
        assert set(r["invariant_errors"]) == {"H", "Lx", "Ly", "Lz"}
        assert max(r["invariant_errors"][k] for k in ("Lx", "Ly", "Lz")) < 1e-13
        assert r["final_error"] is None and r["reference"] is None
        assert 1 <= r["newton_mean"] <= r["newton_max"] <= 10
    em = [r for r in rows if r["method"] == "energy-momentum"]
    mp = [r for r in rows if r["method"] == "midpoint"]
    assert max(r["energy_error"] for r in em) < 1e-13 < min(r["energy_error"] for r in mp)


def test_reference_error_for_the_unperturbed_y0():
    rows = sw.run_sweep(WITH_REF)["rows"]
    assert [r["params"]["k"] for r in rows] == [1.0, 1.5]
    for r in rows:
        assert r["trajectories"] == 1 and r["steps"] == 25 and r["t_final"] == pytest.approx(0.5)
        assert "DOP853" in r["reference"] and 0 < r["final_error"] < 1e-2


def test_chunking_does_not_change_results(monkeypatch):
    spec = {**SMALL, "methods": ["energy-momentum"], "params": {}}
    whole = sw.run_sweep(spec)["rows"]
    monkeypatch.setattr(sw, "CHUNK_VALUES", 3 * 6 * 7)  # 7 steps per chunk
    assert _results(sw.run_sweep(spec)["rows"]) == _results(whole)


def test_constrained_ensemble_projected_for_each_parameter_value():
    rep = sw.run_sweep({"scene": "pendulum", "methods": ["rattle"], "h": 0.05, "steps": 20,
                        "params": {"L": [1.0, 2.0]}, "initial": {"count": 4, "spread": 1e-3, "batch": 4}})
    assert rep["ok"] == 2
    for r in rep["rows"]:
        assert r["constraint_error"] < 1e-12 and r["energy_error"] < 1e-3  # RATTLE: bounded, not exact


def test_numerical_error_is_a_result_not_a_failure():
    rep = sw.run_sweep({"scene": "kepler", "methods": ["midpoint"], "h": [0.01, 0.5], "steps": 20})
    ok, bad = rep["rows"]
    assert ok["status"] == "ok" and rep["failed"] == 0 and rep["numerical_errors"] == 1
    # h = 0.5 does not resolve Kepler (h·ω = 2.19 where Newton fails): a named numerical error
    assert bad["status"] == "numerical-error" and "ResolutionError" in bad["error"]
    assert bad["energy_error"] is None and bad["steps_done"] == 0


_REAL_RUN_TASK = sw.run_task
_ATTEMPTS: dict[str, int] = {}
_ATTEMPTS_LOCK = threading.Lock()


def _failing_run_task(task, src, ref=None):
    """run_task, except that midpoint with h = 0.02 raises a (non-numerical) bug.

    Module level (not a closure): Dask pickles the task function even for threaded
    workers, and a module-level function pickles by reference.
    """
    if task.method == "midpoint" and task.h == 0.02:
        with _ATTEMPTS_LOCK:
            _ATTEMPTS[task.name] = _ATTEMPTS.get(task.name, 0) + 1
        raise KeyError("injected failure")
    return _REAL_RUN_TASK(task, src, ref)


@pytest.fixture
def inject_failure(monkeypatch):
    """Make every midpoint task with h = 0.02 raise; yields the attempt counts per task."""
    _ATTEMPTS.clear()
    monkeypatch.setattr(sw, "run_task", _failing_run_task)
    yield _ATTEMPTS


def test_in_process_failure_retried_then_reported(inject_failure):
    counter = inject_failure
    rep = sw.run_sweep(SMALL, retries=1)
    failed = [r for r in rep["rows"] if r["status"] == "failed"]
    assert rep["tasks"] == 16 and rep["failed"] == len(failed) == 4  # 2 k × 2 batches
    assert all(v == 2 for v in counter.values()) and len(counter) == 4
    for r in failed:
        assert r["method"] == "midpoint" and r["h"] == 0.02 and "injected failure" in r["error"]
        assert r["attempts"] == 2 and r["energy_error"] is None


def test_without_dask_in_process_works_and_workers_is_a_clear_error(monkeypatch, tmp_path, capsys):
    # None in sys.modules makes `import distributed` raise ImportError, as if not installed.
    monkeypatch.setitem(sys.modules, "distributed", None)
    monkeypatch.setitem(sys.modules, "dask", None)
    assert sw.run_sweep(WITH_REF)["ok"] == 2
    with pytest.raises(sw.EngineError, match=r"pip install 'methodgen\[distributed\]'"):
        sw.run_sweep(WITH_REF, workers=2)
    spec = _write(tmp_path, 'scene = "kepler"\nmethods = ["midpoint"]\nh = 0.01\nsteps = 10\n')
    assert main(["sweep", str(spec), "--workers", "2"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Dask, which is not installed" in err
    assert isinstance(sw.EngineError("x"), MethodgenError)


# --- Dask -----------------------------------------------------------------------------------

# Not importorskip at module level: without dask the in-process tests above must still run.
requires_dask = pytest.mark.skipif(importlib.util.find_spec("distributed") is None,
                                   reason="needs methodgen[distributed]")


@requires_dask
def test_local_cluster_matches_in_process():
    """workers=2: a LocalCluster of 2 single-threaded *processes* (the production path:
    tasks, module sources and results really cross process boundaries)."""
    local = sw.run_sweep(SMALL)
    remote = sw.run_sweep(SMALL, workers=2)
    assert remote["engine"]["kind"] == "local-cluster" and remote["engine"]["workers"] == 2
    assert remote["tasks"] == 16 and remote["failed"] == 0
    # The same code on the same inputs: bitwise equal, not just close.
    assert _results(remote["rows"]) == _results(local["rows"])
    assert remote["trajectory_steps"] == local["trajectory_steps"]


@pytest.fixture(scope="module")
def threaded_cluster():
    """Threads, not processes: the failure injection below monkeypatches this process's
    methodgen.app.sweep, which worker threads share (worker processes would not see it)."""
    import distributed

    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=False,
                                  dashboard_address=None) as cluster:
        yield cluster


@requires_dask
def test_scheduler_failure_retried_then_reported(inject_failure, threaded_cluster):
    counter = inject_failure
    rep = sw.run_sweep(SMALL, scheduler=threaded_cluster.scheduler_address, retries=2)
    assert rep["engine"]["kind"] == "scheduler" and rep["engine"]["workers"] == 2
    assert rep["tasks"] == 16 and rep["ok"] == 12 and rep["failed"] == 4  # reported, not dropped
    assert len(counter) == 4 and all(v == 3 for v in counter.values())  # 1 + 2 retries each
    for r in rep["rows"]:
        if r["status"] == "failed":
            assert (r["method"], r["h"]) == ("midpoint", 0.02)
            assert "KeyError" in r["error"] and "injected failure" in r["error"]


@requires_dask
def test_references_as_dask_tasks_match_in_process(threaded_cluster):
    remote = sw.run_sweep(WITH_REF, scheduler=threaded_cluster.scheduler_address)
    assert _results(remote["rows"]) == _results(sw.run_sweep(WITH_REF)["rows"])


@requires_dask
def test_unreachable_scheduler_is_a_clean_error():
    import dask

    # Port 9 on loopback (discard): nothing listens; the client retries until the
    # connect timeout, shortened here.
    with dask.config.set({"distributed.comm.timeouts.connect": "1s"}):
        with pytest.raises(sw.EngineError, match="cannot connect to the Dask scheduler"):
            sw.run_sweep(WITH_REF, scheduler="tcp://127.0.0.1:9")


def test_shipped_source_used_where_the_driver_file_is_missing(tmp_path, monkeypatch):
    """A remote worker: the driver's path does not exist there; the source goes to its cache."""
    monkeypatch.setenv("METHODGEN_CACHE", str(tmp_path / "cache"))
    monkeypatch.setattr(sw, "_MODULES", {})
    src = sw.plan_sweep(sw.parse_spec(WITH_REF)).modules["energy-momentum"]
    remote = sw.ModuleSource(src.method, src.signature, str(tmp_path / "elsewhere" / "x.py"), src.filename,
                             src.source)
    module = sw.load_shipped_module(remote)
    assert Path(module.__file__) == (tmp_path / "cache" / src.filename).resolve()
    assert module.SIGNATURE == src.signature


# --- CLI ----------------------------------------------------------------------------------------

def test_cli_json_is_one_object_and_csv(tmp_path):
    spec = _write(tmp_path, 'scene = "harmonic"\nmethods = ["midpoint"]\nh = [0.1, 0.05]\nsteps = 40\n'
                            '[params]\nk = [1.0, 4.0]\n')
    csv_path = tmp_path / "out.csv"
    res = subprocess.run([sys.executable, "-m", "methodgen", "sweep", str(spec), "--json", "--csv",
                          str(csv_path)], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    rep = json.loads(res.stdout)  # exactly one JSON object: json.loads rejects trailing data
    assert rep["tasks"] == 4 and [r["task"] for r in rep["rows"]] == [
        "midpoint h=0.05 k=1.0 batch=0", "midpoint h=0.05 k=4.0 batch=0",
        "midpoint h=0.1 k=1.0 batch=0", "midpoint h=0.1 k=4.0 batch=0"]
    assert all(r["reference"].startswith("exact (matrix exponential") for r in rep["rows"])
    err = [r["final_error"] for r in rep["rows"]]
    # Midpoint: the error grows with h·ω (ω = √k) and shrinks with h.
    assert 0 < err[0] < err[1] < 0.05 and err[0] < err[2] < err[3] < 0.05
    lines = csv_path.read_text().splitlines()
    assert len(lines) == 5 and lines[0].startswith("task,status,method,h,") and "param_k" in lines[0]
    assert lines[1].split(",")[0] == "midpoint h=0.05 k=1.0 batch=0"


def test_cli_failed_task_exits_nonzero(inject_failure, tmp_path, capsys):
    spec = _write(tmp_path, 'scene = "kepler"\nmethods = ["midpoint"]\nh = [0.02, 0.01]\nsteps = 10\n')
    assert main(["sweep", str(spec), "--json", "--retries", "0"]) == 1
    out, err = capsys.readouterr()
    rep = json.loads(out)
    assert [r["status"] for r in rep["rows"]] == ["ok", "failed"]
    assert "1 of 2 sweep tasks failed" in err


def test_cli_spec_error_is_one_line_exit_2(tmp_path, capsys):
    spec = _write(tmp_path, 'scene = "kepler"\nh = [0.01]\nstep = 10\n')
    assert main(["sweep", str(spec)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "unknown key(s) ['step']" in err


def test_cli_rejects_workers_and_scheduler_together(tmp_path, capsys):
    with pytest.raises(SystemExit) as exc:
        main(["sweep", "spec.toml", "--workers", "2", "--scheduler", "tcp://127.0.0.1:9"])
    assert exc.value.code == 2 and "not allowed with" in capsys.readouterr().err
