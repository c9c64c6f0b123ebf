"""The model card names where the training data came from."""

import json

import pytest
from checks import REFERENCE_MODELS_DIR

from tactile_manip.learning.card import model_card
from tactile_manip.perception.reconstruct import read_metadata

# a reference model shipped with its training history (the default model's image graphs are the robust one's)
SHIPPED_MODEL = REFERENCE_MODELS_DIR / "supermag_fast.onnx"


@pytest.fixture(scope="module")
def shipped():
    history = json.loads(SHIPPED_MODEL.with_suffix(".history.json").read_text())
    return read_metadata(SHIPPED_MODEL), history


@pytest.mark.parametrize("source, says", [
    ("tactile-manip simulate", "simulated pairs"),
    (None, "simulated pairs"),  # written by `simulate` before it recorded its name
    ("tactile-manip import", "pairs (tactile-manip import)"),
])
def test_card_names_the_data_source(shipped, source, says):
    meta, history = shipped
    meta = dict(meta, training_data=dict(meta.get("training_data", {}), source=source))
    card = model_card(meta, history)
    assert f"7290 {says}" in card
    assert ("one default sensor pair" in card) == (says == "simulated pairs")
    assert "(None)" not in card
