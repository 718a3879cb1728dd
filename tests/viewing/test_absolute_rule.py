"""The absolute opacity rule through the one builder: ``vimsim render``/``epof``'s options,
a manifest's ``[epof]`` table and a study's EPOF task give the same rule; bad values are
named as each caller spells them."""

from __future__ import annotations

import argparse

import pytest

from simulator.core.errors import InputError
from simulator.mitigation.bands import ABSOLUTE_HIGH_DPS, ABSOLUTE_LOW_DPS
from simulator.viewing.spec import ViewSpec


def _cli_args(command: str, *argv: str) -> argparse.Namespace:
    from simulator.cli import build_parser

    extra = ["v.mp4", "p.csv", "-o", "o"] if command == "render" else ["g.npz", "p.csv", "-o", "o.csv"]
    return build_parser().parse_args([command, *extra, *argv])


def test_cli_and_table_give_the_same_absolute_rule():
    from simulator.commands._opacity import rule_from_args

    argv = ("--opacity-rule", "absolute", "--low-dps", "4", "--high-dps", "25")
    table = {"opacity_rule": "absolute", "low_dps": 4, "high_dps": 25}
    a, b = ViewSpec.from_options(_cli_args("render", *argv)).rule, ViewSpec.from_options(table).rule
    assert a == b == rule_from_args(_cli_args("epof", *argv))
    assert a.is_absolute and a.fit(None, [1.0, 2.0]) == (4.0, 25.0)
    assert a.ease_in_s > 0  # eased as the comfort rule
    d = ViewSpec.from_options({"opacity_rule": "absolute"}).rule  # the bands' edges by default
    assert (d.low_dps, d.high_dps) == (ABSOLUTE_LOW_DPS, ABSOLUTE_HIGH_DPS)
    # The default (issue 37): the absolute rule at the bands' edges, named so in every record.
    assert ViewSpec.from_options({}).rule == d and d.describe()["name"] == "absolute"
    assert rule_from_args(_cli_args("epof")) == d == ViewSpec.from_options(_cli_args("render")).rule
    paper = ViewSpec.from_options({"opacity_rule": "paper"}).rule
    assert not paper.is_absolute and paper.is_paper and paper.describe()["name"] == "paper"


@pytest.mark.parametrize(
    ("argv", "table", "cli_name", "key"),
    [
        (["--opacity-rule", "paper", "--low-dps", "3"], {"opacity_rule": "paper", "low_dps": 3},
         "--low-dps", "low_dps"),
        (["--opacity-rule", "absolute", "--low-dps", "30", "--high-dps", "5"],
         {"opacity_rule": "absolute", "low_dps": 30, "high_dps": 5}, "--low-dps", "low_dps"),
    ],
)  # fmt: skip
def test_absolute_messages_name_the_option(argv, table, cli_name, key):
    with pytest.raises(InputError, match=cli_name):
        ViewSpec.from_options(_cli_args("render", *argv))
    with pytest.raises(InputError, match=f"\\[epof\\] {key}"):
        ViewSpec.from_options(table, label=lambda k: f"[epof] {k}")


def test_manifest_absolute_rule_reaches_epof_task_and_render_view(tmp_path):
    """``[epof] opacity_rule = "absolute"``: the EPOF task's rule and the render view's rule
    are the same rule (the one builder), with the manifest's deg/s."""
    from simulator.study.manifest import load_manifest
    from simulator.study.tasks import _rule

    (tmp_path / "v.mp4").write_bytes(b"x")
    (tmp_path / "p.csv").write_text("time_s,yaw_deg,pitch_deg,roll_deg\n0,0,0,0\n1,0,0,0\n")
    m = tmp_path / "s.toml"
    body = ('[[videos]]\nid = "v"\npath = "v.mp4"\n\n[[viewings]]\nvideo = "v"\ntrace = "p.csv"\n'
            '\n[epof]\nopacity_rule = "absolute"\nhigh_dps = 40\n')  # fmt: skip
    m.write_text(body)
    man = load_manifest(m)
    view_rule = ViewSpec.from_options(man.render["view"]).rule
    assert _rule(man.epof) == view_rule
    assert (view_rule.low_dps, view_rule.high_dps) == (ABSOLUTE_LOW_DPS, 40.0)
    m.write_text(body.replace("high_dps = 40", "high_dps = 2"))
    with pytest.raises(InputError, match=r"\[epof\] low_dps"):
        load_manifest(m)
    m.write_text(body.replace('opacity_rule = "absolute"\n', 'opacity_rule = "comfort"\n'))
    with pytest.raises(InputError, match=r"\[epof\] high_dps needs"):
        load_manifest(m)
    m.write_text(body.replace('opacity_rule = "absolute"\n', ""))  # the default: absolute
    assert _rule(load_manifest(m).epof) == view_rule
