"""Fuzzed scanner model / calibration JSON (`ScannerModel.load`): CalibrationError naming
the file, or a model whose every value is finite and which reads back as itself."""

from __future__ import annotations

import json

from hypothesis import given
from hypothesis import strategies as st

from scanmap_driver.errors import CalibrationError
from scanmap_driver.scanner_model import ScannerModel, reference_scanner

from .mutations import FUZZ, every_json_mutation, finite_json, mutated_json, read_within

ORIGINAL = reference_scanner().to_dict()


@FUZZ
@given(data=st.data())
def test_fuzzed_scanner_file_is_refused_or_read_whole(tmp_path_factory, data):
    path = tmp_path_factory.mktemp("model") / "scanner.json"
    path.write_text(data.draw(mutated_json(ORIGINAL)))
    model = read_within(lambda: ScannerModel.load(path), CalibrationError, path)
    if model is None:
        return
    again = ScannerModel.from_dict(finite_json(model.to_dict()))
    assert again.to_dict() == model.to_dict()
    stored = json.loads(path.read_text())
    assert stored.get("name", model.name) == model.name  # a name is a string, not coerced


def test_every_field_deleted_or_hostile_is_refused_or_kept_as_written():
    for path, tree in every_json_mutation(ORIGINAL):
        try:
            value = ScannerModel.from_dict(tree, source="sweep.json")
        except CalibrationError as exc:
            assert "sweep.json" in str(exc)
            continue
        written = finite_json(value.to_dict())
        for key in path[:-1]:
            written, tree = written[key], tree[key]
        kept = path[-1] in tree and path[-1] in written  # to_dict leaves out defaults
        if kept and not isinstance(tree[path[-1]], dict):
            assert written[path[-1]] == tree[path[-1]], path
