"""Speed against error for every stage: `python -m benchmarks [--quick]`.

Each `bench_<topic>.py` module exposes `run(quick: bool) -> list[dict]`; a row holds
stage, method, settings, median_s (per frame, scan or query), error, error_unit and
peers ({name: {"median_s": ..., "error": ...}}) measured in the same run.
"""
