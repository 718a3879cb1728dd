"""The table of flow backends: names, ``--flow`` spellings and help, light enough for the CLI.

Each backend lives in its own module of :mod:`simulator.flow` (``dis``, ``farneback``,
``torchscript``) whose class subclasses :class:`simulator.flow.base.FlowBackend`, declares
its native stride and registers itself with :func:`simulator.flow.base.register`. The one
entry here names that module, how ``--flow`` spells it and a short help: the CLI builds its
help text from this table without importing numpy or OpenCV, and
:func:`simulator.flow.base.make_backend` imports the module named here on first use.

A new backend: one new module (the class, decorated with ``@register``) and one
:class:`FlowEntry` below.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["BACKENDS", "FLOW_CHOICES", "FlowEntry", "entry", "flow_help"]


@dataclass(frozen=True)
class FlowEntry:
    """One backend as the CLI sees it.

    Attributes
    ----------
    name : the text before ``:`` in ``--flow`` (lower case)
    module : the module under :mod:`simulator.flow` defining and registering the class
    spellings : every ``--flow`` spelling, for the help (``"dis:fast"``, ``"torch:MODEL.pt"``)
    help : a few words for ``--help``
    """

    name: str
    module: str
    spellings: tuple[str, ...]
    help: str


#: Every backend, in the order ``--help`` lists them; the first is the default.
BACKENDS: tuple[FlowEntry, ...] = (
    FlowEntry(
        "dis",
        "dis",
        ("dis", "dis:ultrafast", "dis:fast", "dis:medium", "dis:PRESET+refineN"),
        "dis (OpenCV DIS ultrafast, default), dis:fast, dis:medium, dis:ultrafast+refine5 "
        "(5 variational-refinement iterations: slow motion read better, ~20 %% slower)",
    ),
    FlowEntry("farneback", "farneback", ("farneback",), "farneback (OpenCV Farneback)"),
    FlowEntry(
        "torch",
        "torchscript",
        ("torch:MODEL.pt",),
        "torch:MODEL.pt (TorchScript (N,3,H,W) x2 -> (N,2,H,W) pixel flow; the model file "
        "runs as code: trusted files only)",
    ),
)

#: Every ``--flow`` spelling, comma-separated (error messages and docs).
FLOW_CHOICES: str = ", ".join(s for e in BACKENDS for s in e.spellings)


def entry(name: str) -> FlowEntry | None:
    """The entry of a backend name (case-insensitive), or None."""
    key = name.strip().lower()
    return next((e for e in BACKENDS if e.name == key), None)


def flow_help() -> str:
    """The ``--flow`` help text: every backend's spellings and words."""
    return "flow backend: " + "; ".join(e.help for e in BACKENDS)
