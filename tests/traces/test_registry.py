"""The head-trace format registry: each reader module declares its formats and how to recognise them."""

from __future__ import annotations

from simulator.core.choices import HEADPATH_FORMATS
from simulator.traces.path import HeadPath
from simulator.traces.readers import REGISTRY, detect_format, load_headpath, n_users
from simulator.traces.readers.formats import TraceFormat


def test_registry_names_are_the_cli_choices():
    assert set(REGISTRY) == set(HEADPATH_FORMATS)
    assert all(isinstance(f, TraceFormat) and f.name == k for k, f in REGISTRY.items())


def test_a_new_format_is_one_entry(tmp_path, monkeypatch):
    """A format added to the registry is detected and read without touching detection code."""
    calls = []

    def read(p, **_):
        calls.append(p)
        return HeadPath.from_angles_deg([0.0, 1.0], [0.0, 10.0], 0.0, 0.0, source=str(p))

    fmt = TraceFormat("mylab", read, lambda s: s.has("mylab_time"), rank=1)
    monkeypatch.setitem(REGISTRY, "mylab", fmt)
    p = tmp_path / "log.txt"
    p.write_text("mylab_time head\n0 1\n")
    assert detect_format(p) == "mylab"
    assert load_headpath(p).n == 2 and calls == [p]
    assert n_users(p) == ("mylab", 1)


def test_counting_users_without_parsing(tmp_path):
    p = tmp_path / "agg.txt"
    p.write_text("0 0.1 0.2\n" + "0 0 0\n0 0 0\n" * 3)
    assert n_users(p) == ("360vidstr", 3)
