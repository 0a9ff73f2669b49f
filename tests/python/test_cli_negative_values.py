"""Option values that start with '-': coordinates, offsets and heights are
negative as often as not, and argparse alone took ``--tool-ball -5,0,150``
or ``--height -1e-3`` for an unknown option ("expected one argument")."""
from __future__ import annotations

import pytest

import fivecal
from fivecal import cli
from fivecal.demo import example_machine_path

C600U = example_machine_path("c600u")


def test_negative_coordinates_reach_the_import(tmp_path):
    f = tmp_path / "r.csv"
    f.write_text("X,Y,Z,A,C,dx_um,dy_um,dz_um\n50,-40,-80.718,-30,0,-29.6,7.2,23.0\n", encoding="utf-8")
    out = tmp_path / "ds.json"
    rc = cli.main(["import", "rtest", str(f), "--machine", C600U, "--setup", "R1",
                   "--tool-ball", "-5,0,1.5e2", "--table-ball", "-50.5,-1e1,80", "--out", str(out)])
    assert rc == 0
    o = fivecal.load_dataset(out).observations[0]
    assert o["tool_ball"] == [-5.0, 0.0, 150.0] and o["table_ball"] == [-50.5, -10.0, 80.0]


@pytest.mark.parametrize("value,ok", [("-1e-3", True), ("-5,0,100", True), ("-.5", True), ("-2.5E+1", True),
                                      ("-x", False), ("--out", False), ("-5,a", False)])
def test_which_tokens_count_as_values(value, ok):
    p = cli._Parser(prog="t")
    p.add_argument("--v")
    p.add_argument("-x", action="store_true")
    if ok:
        assert p.parse_args(["--v", value]).v == value
    else:
        with pytest.raises(SystemExit):
            p.parse_args(["--v", value])


def test_an_unknown_short_option_is_still_an_error(capsys):
    with pytest.raises(SystemExit) as e:
        cli.main(["identify", "d.json", "-q"])
    assert e.value.code == 2 and "-q" in capsys.readouterr().err
