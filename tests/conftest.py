"""Shared fixtures: the built-in systems and their generated modules (in a temp folder)."""

from __future__ import annotations

import numpy as np
import pytest

import methodgen as mg

KEPLER_Y0 = np.array([0.4, 0.0, 0.0, 0.0, 1.6, 1.2])


@pytest.fixture(scope="session")
def kepler():
    return mg.load_scene("kepler").system


@pytest.fixture(scope="session")
def harmonic():
    return mg.load_scene("harmonic").system


@pytest.fixture(scope="session")
def modules(tmp_path_factory):
    """Generate (once per session) a module per (scene, method) into a temp folder."""
    cache = {}
    root = tmp_path_factory.mktemp("generated")

    def get(system, method):
        key = (system.fingerprint(), method)
        if key not in cache:
            scheme = mg.discretize(system, method)
            path = root / f"{system.name}_{method.replace('-', '_')}.py"
            cache[key] = (scheme, mg.generate(scheme, path))
        return cache[key]

    return get
