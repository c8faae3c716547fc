"""The benchmarks find every corrected CARMEN log in the folder, not just the shared seven."""

from __future__ import annotations

from benchmarks.carmen_logs import carmen_logs, carmen_path


def test_a_log_added_beside_the_shared_ones_is_found_after_them(tmp_path):
    for name in ("zeta-corrected.log.gz", "intel-corrected.log.gz", "alpha-corrected.log",
                 "raw.log", "notes.txt", "fhw-corrected.log.gz.part"):
        (tmp_path / name).write_bytes(b"")
    (tmp_path / "dir-corrected.log").mkdir()
    assert carmen_logs(("fhw", "intel"), tmp_path) == ("intel", "alpha", "zeta")
    assert carmen_path("alpha", tmp_path) == tmp_path / "alpha-corrected.log"
    assert carmen_path("zeta", tmp_path) == tmp_path / "zeta-corrected.log.gz"


def test_an_absent_folder_has_no_logs_and_a_missing_log_names_its_file(tmp_path):
    assert carmen_logs(folder=tmp_path / "absent") == ()
    assert carmen_path("intel", tmp_path) == tmp_path / "intel-corrected.log.gz"
