"""`scanmap bench` finds a checkout and runs `python -m benchmarks` there, flags passed on."""

from __future__ import annotations

import json
import sys
from pathlib import Path

from scanmap.cli import main

ROOT = Path(__file__).resolve().parents[2]

FAKE_MAIN = """import json, os, sys
with open(os.environ["BENCH_PROBE"], "w") as f:
    json.dump({"argv": sys.argv[1:], "executable": sys.executable, "cwd": os.getcwd()}, f)
sys.exit(3)
"""


def test_flags_reach_python_m_benchmarks_in_the_checkout(tmp_path, monkeypatch):
    repo = tmp_path / "checkout"
    (repo / "benchmarks").mkdir(parents=True)
    (repo / "benchmarks" / "__init__.py").write_text("")
    (repo / "benchmarks" / "__main__.py").write_text(FAKE_MAIN)
    probe = tmp_path / "probe.json"
    monkeypatch.setenv("BENCH_PROBE", str(probe))
    code = main(["bench", "--quick", "--only", "grid", "laser", "--out", str(tmp_path / "r"),
                 "--repo", str(repo)])
    assert code == 3  # the benchmarks' exit code is the command's
    seen = json.loads(probe.read_text())
    assert seen["argv"] == ["--quick", "--only", "grid", "laser", "--out", str(tmp_path / "r")]
    assert seen["executable"] == sys.executable
    assert Path(seen["cwd"]) == repo.resolve()


def test_a_folder_without_benchmarks_is_refused_with_what_to_do(tmp_path, capsys):
    assert main(["bench", "--repo", str(tmp_path)]) == 1
    err = capsys.readouterr().err
    assert str(tmp_path) in err and "not a scanmap source checkout" in err


def test_outside_a_checkout_without_an_editable_install_it_says_what_to_do(tmp_path, capsys,
                                                                             monkeypatch):
    from scanmap.cli.commands import bench

    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(bench, "editable_checkout", lambda: None)
    assert main(["bench", "--quick"]) == 1
    err = capsys.readouterr().err
    assert "no source checkout was found" in err and "--repo PATH" in err


def test_the_editable_install_is_this_checkout():
    from scanmap.cli.commands.bench import editable_checkout

    assert editable_checkout() == ROOT


def test_a_real_run_from_the_checkout(tmp_path, monkeypatch):
    monkeypatch.chdir(ROOT)
    out = tmp_path / "results"
    assert main(["bench", "--quick", "--only", "triangulation", "--out", str(out)]) == 0
    result = json.loads((out / "latest.json").read_text())
    assert result["quick"] is True and result["only"] == ["triangulation"]
    assert result["rows"] and all(r["stage"] == "triangulation" for r in result["rows"])
