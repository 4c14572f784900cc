"""Shared fixtures: the OpenCL runtime and the location of ../shared test data."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

SHARED = Path(__file__).resolve().parents[2] / "shared"
# The fitting and sweep scripts live outside the wheel in research/; the tests of what they make import them.
RESEARCH = Path(__file__).resolve().parents[1] / "research"
sys.path.append(str(RESEARCH))


def shared_path(*parts: str) -> Path:
    """A path under ../shared, or skip the test saying the data folder is missing."""
    path = SHARED.joinpath(*parts)
    if not path.exists():
        pytest.skip(f"test data {path} is absent (it lives in the workplace's shared/ folder beside the repo)")
    return path


@pytest.fixture(scope="session")
def runtime():
    from lfcl.device import get_runtime

    return get_runtime()


@pytest.fixture
def rng():
    return np.random.default_rng(1234)


def relative_dot_error(lhs: float, rhs: float) -> float:
    """|<Ax, y> - <x, A^T y>| relative to the larger magnitude (PyLops-style dot test)."""
    return abs(lhs - rhs) / max(abs(lhs), abs(rhs), 1e-30)


def pytest_report_header(config):
    import lfcl

    return f"lfcl {lfcl.__version__} imported from {Path(lfcl.__file__).parent}"


def pytest_sessionstart(session):
    # CI tests the installed wheel: make sure the source tree did not shadow it.
    import os

    import lfcl

    if os.environ.get("LFCL_TEST_INSTALLED") == "1":
        repo_package = Path(__file__).resolve().parents[1] / "lfcl"
        if Path(lfcl.__file__).resolve().parent == repo_package:
            raise pytest.UsageError(f"LFCL_TEST_INSTALLED=1 but lfcl was imported from the source tree {repo_package}")
