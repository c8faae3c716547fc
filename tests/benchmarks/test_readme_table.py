"""README.md's benchmark table is the one the saved results give, row for row."""

from __future__ import annotations

import json

from benchmarks.readme_table import BEGIN, END, README, RESULTS, highlight_rows, render
from benchmarks.report import markdown_table


def test_the_readme_table_is_generated_from_the_saved_results():
    result = json.loads(RESULTS.read_text())
    text = README.read_text()
    block = text[text.index(BEGIN):text.index(END) + len(END)]
    assert block == render(result), (
        "README.md's benchmark table differs from benchmarks/results/latest.json: run "
        "`python -m benchmarks.readme_table`")


def test_every_highlight_is_a_row_of_the_full_table():
    result = json.loads(RESULTS.read_text())
    full = (RESULTS.parent / "latest.md").read_text().splitlines()
    rows = highlight_rows(result["rows"])
    assert rows, "no highlighted row found in the results"
    for line in markdown_table(rows).splitlines()[2:]:
        assert line in full


def test_the_stamp_names_the_cpu_the_kernels_were_compiled_for():
    """Two machines that both call themselves "AMD EPYC" ran the vectorised laser kernels
    3x apart: the stamp names the CPU target (LLVM's, what Numba compiles for) when the
    run recorded it, and still reads a run that did not."""
    from benchmarks.__main__ import _machine
    from benchmarks.readme_table import stamp_line

    machine = _machine()
    assert machine["cpu_target"]  # LLVM's name of this CPU, e.g. znver3
    result = {"created": "2026-11-27T11:12:17", "commit": "f3b789d", "quick": False}
    assert f"({machine['cpu_target']}, {machine['cores']} cores)" in stamp_line(
        {**result, "machine": machine})
    old = {key: value for key, value in machine.items() if key != "cpu_target"}
    assert f"{machine['cpu_model']} ({machine['cores']} cores)" in stamp_line(
        {**result, "machine": old})
