"""Fuzzed scanner model / calibration JSON (`ScannerModel.load`): CalibrationError naming
the file, or a model whose every value is finite and which reads back as itself."""

from __future__ import annotations

import json

from hypothesis import given
from hypothesis import strategies as st

from scanmap_driver.errors import CalibrationError
from scanmap_driver.scanner_model import ScannerModel, reference_scanner

from .mutations import FUZZ, finite_json, mutated_json, read_within, sweep_json_reader

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
    sweep_json_reader(ORIGINAL, ScannerModel.from_dict, CalibrationError)
