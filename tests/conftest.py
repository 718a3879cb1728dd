"""Shared test fixtures.

``shared_dir`` is ``../shared`` beside the checkout (CI has it there); tests needing real
third-party data skip with a clear reason only where that folder is really absent.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SHARED = Path(os.environ.get("VIMSIM_SHARED", REPO.parent / "shared"))
REAL = SHARED / "data" / "real"
OUT = REPO / "tests" / "_out"


@pytest.fixture(scope="session")
def shared_dir() -> Path:
    if not SHARED.is_dir():
        pytest.skip(f"../shared not found at {SHARED} (CI has it beside the checkout)")
    return SHARED


@pytest.fixture(scope="session")
def real_dir(shared_dir: Path) -> Path:
    return shared_dir / "data" / "real"


@pytest.fixture(scope="session")
def out_dir() -> Path:
    """Folder for files tests write for a person to look at (failing frames etc.)."""
    OUT.mkdir(parents=True, exist_ok=True)
    return OUT


@pytest.fixture(scope="session", autouse=True)
def _map_cache_dir(tmp_path_factory) -> Path:
    """Tests (and the CLI subprocesses they start) use a temporary map cache, never the
    user's (:mod:`simulator.core.mapcache`)."""
    d = tmp_path_factory.mktemp("vimsim-cache")
    old = os.environ.get("VIMSIM_CACHE_DIR")
    os.environ["VIMSIM_CACHE_DIR"] = str(d)
    yield d
    if old is None:
        os.environ.pop("VIMSIM_CACHE_DIR", None)
    else:
        os.environ["VIMSIM_CACHE_DIR"] = old


@pytest.fixture(scope="module")
def ctx():
    """A headless EGL context (moderngl) per test module, released at the module's end;
    skips only where creating one fails (CI installs libegl1 + libgl1-mesa-dri), and no
    GL error is left at the end."""
    from simulator.core.errors import InputError
    from simulator.render import create_context

    try:
        c = create_context()
    except InputError as e:
        pytest.skip(f"headless EGL absent on this machine ({e})")
    try:
        assert c.error == "GL_NO_ERROR"
        yield c
        assert c.error == "GL_NO_ERROR"
    finally:
        c.release()


#: Fixtures that decide a marker: a test using one gets it (with the explicit marks on
#: tests that make a context or read the data some other way, e.g. through the CLI).
FIXTURE_MARKERS = {
    "ctx": "gl",
    "real_dir": "real_data",
    "shared_dir": "real_data",
    "browser": "browser",
}


def pytest_collection_modifyitems(config, items):
    """``gl`` on every test given the GL context fixture, ``real_data`` on every test
    given the real-data folder, so that ``-m "not gl"`` / ``-m "not real_data"`` select
    what runs without them."""
    for item in items:
        for fixture in set(getattr(item, "fixturenames", ())) & FIXTURE_MARKERS.keys():
            item.add_marker(FIXTURE_MARKERS[fixture])


@pytest.fixture(scope="session")
def browser():
    """One headless Chromium session for every ``browser`` test (tests/browser_support.py);
    a missing browser fails the test with the reason (make test installs it)."""
    from browser_support import Browser, available  # tests/ is on sys.path (conftest's folder)

    why = available()
    if why:
        pytest.fail(f"browser test cannot run: {why}")
    b = Browser()
    try:
        yield b
    finally:
        b.close()
