"""Fixtures of the export tests: the exported C# runtime and its test harness, compiled by Mono."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
CS_DIR = REPO / "simulator" / "export" / "unity"
HARNESS = REPO / "tests" / "export" / "cs" / "EpofHarness.cs"


@pytest.fixture(scope="session")
def harness(tmp_path_factory) -> Path:
    """The C# runtime and the test harness, compiled by Mono's mcs (make test installs it)."""
    mcs, mono = shutil.which("mcs"), shutil.which("mono")
    if mcs is None or mono is None:
        pytest.skip(
            "Mono's C# compiler (mcs) or runtime (mono) not found; `make sysdeps` installs "
            "the Debian packages mono-mcs mono-runtime"
        )
    out = tmp_path_factory.mktemp("cs") / "harness.exe"
    r = subprocess.run(
        [
            mcs,
            "-optimize+",
            "-warnaserror+",
            f"-out:{out}",
            str(CS_DIR / "VimsimEpof.cs"),
            str(HARNESS),
        ],
        capture_output=True,
        text=True,
        check=False,
    )
    assert r.returncode == 0, r.stdout + r.stderr
    return out
