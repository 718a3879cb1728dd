"""The reliability corpus (round 3) run against two checkouts: cases correct per
contract, by class, this checkout side by side with another (``--before DIR``, e.g. a
``git archive`` of main's commit before the change).

The corpus is this checkout's tests of bad inputs and faults: the earlier table
(``tests/test_reliability.py``), round 3's (``tests/test_reliability_r3.py``), a real full
disk under every writer (``tests/test_full_disk.py``), the output-file helper
(``tests/core/test_fileio.py``), the study's import path and grid cache
(``tests/study/test_study_import_path.py``, ``tests/study/test_study_cache.py``) and the
fuzzed readers (``tests/test_fuzz.py``, its default short run). Each test case counts
once; a case passes when the checkout meets the contract it checks. The other checkout
is imported instead of this one (``PYTHONPATH``, run from its folder). Signal tests are
left out: they changed how they test (a known point), not what they test.

Run: .venv/bin/python bench/reliability_corpus.py --before /tmp/main-e8a4aea
"""

from __future__ import annotations

import argparse
import collections
import os
import subprocess
import sys
import tempfile
import xml.etree.ElementTree as ET
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
FILES = [
    "tests/test_reliability.py",
    "tests/test_reliability_r3.py",
    "tests/test_full_disk.py",
    "tests/core/test_fileio.py",
    "tests/study/test_study_import_path.py",
    "tests/study/test_study_cache.py",
    "tests/test_fuzz.py",
]
sys.path.insert(0, str(REPO / "tests"))


def _class(file: str, name: str) -> str:
    from test_reliability_r3 import case_class

    if "test_corpus_r3[" in name:
        return "r3 " + case_class(name.split("[", 1)[1].rstrip("]"))
    if "test_corpus[" in name:
        return "earlier table"
    stem = Path(file).stem
    return {
        "test_reliability": "earlier faults",
        "test_reliability_r3": "r3 other",
        "test_full_disk": "full disk (tmpfs)",
        "test_fileio": "output-file helper",
        "test_study_import_path": "study import path",
        "test_study_cache": "study cache / non-video",
        "test_fuzz": "fuzzed readers",
    }.get(stem, stem)


def run(code: Path) -> dict[str, tuple[str, bool]]:
    """``{test id: (class, passed)}`` with ``code``'s package imported."""
    with tempfile.TemporaryDirectory() as t:
        xml = Path(t) / "r.xml"
        env = dict(os.environ, PYTHONPATH=str(code), MPLBACKEND="Agg")
        subprocess.run(  # memory capped: a case that allocates without bound fails, not the run
            ["prlimit", f"--as={12 * 2**30}", sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-k", "not signal",
             f"--junitxml={xml}", "--rootdir", str(REPO), *(str(REPO / f) for f in FILES)],
            cwd=code, env=env, check=False, capture_output=True, text=True,
        )  # fmt: skip
        if not xml.is_file():
            raise SystemExit(f"pytest gave no report for {code}")
        out = {}
        for tc in ET.parse(xml).getroot().iter("testcase"):
            name = tc.get("name", "")
            file = tc.get("file") or tc.get("classname", "").replace(".", "/") + ".py"
            bad = any(c.tag in ("failure", "error") for c in tc)
            skipped = any(c.tag == "skipped" for c in tc)
            if skipped:
                continue
            out[f"{tc.get('classname')}::{name}"] = (_class(file, name), not bad)
        return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--before", type=Path, help="another checkout (the package folder's parent)")
    args = ap.parse_args()
    now = run(REPO)
    before = run(args.before) if args.before else {}
    rows = collections.defaultdict(lambda: [0, 0, 0])
    for tid, (cls, ok) in now.items():
        r = rows[cls]
        r[0] += 1
        r[1] += ok
        r[2] += before.get(tid, (cls, False))[1]
    print(f"{'class':28s} {'cases':>5s} {'now ok':>7s} {'before ok':>9s}")
    tot = [0, 0, 0]
    for cls in sorted(rows):
        n, ok, ob = rows[cls]
        tot = [tot[0] + n, tot[1] + ok, tot[2] + ob]
        print(f"{cls:28s} {n:5d} {ok:7d} {ob if before else '-':>9}")
    print(f"{'total':28s} {tot[0]:5d} {tot[1]:7d} {tot[2] if before else '-':>9}")
    if before:
        print(f"ratio correct now / before: {tot[1] / max(tot[2], 1):.2f}")
        fails = sorted(t for t, (_, ok) in now.items() if not ok)
        print("failing now:", fails[:20] or "none")


if __name__ == "__main__":
    main()
