"""Each model card is headed by its model's name, so that the cards of several models tell themselves apart."""

import json
from pathlib import Path

import pytest
from checks import REFERENCE_MODELS, REFERENCE_MODELS_DIR

from tactile_manip.learning.card import model_card
from tactile_manip.perception.reconstruct import read_metadata

pytest.importorskip("onnx", reason="reading the shipped model's metadata needs onnx (extra 'train')")


def test_card_title_names_the_model():
    path = REFERENCE_MODELS_DIR / "supermag_fast.onnx"  # a reference model with its training history beside it
    history = json.loads(path.with_suffix(".history.json").read_text())
    meta = read_metadata(path)
    titles = {model_card(meta, history, name=n).splitlines()[0] for n in ("supermag_fast", "other")}
    assert titles == {"# `supermag_fast`: SuperMag CVAE, `compact` preset",
                      "# `other`: SuperMag CVAE, `compact` preset"}
    assert model_card(meta, history).splitlines()[0] == "# SuperMag CVAE, `compact` preset"


def test_shipped_cards_have_their_own_titles():
    files = REFERENCE_MODELS  # the cards of the models trained on their own
    titles = [(REFERENCE_MODELS_DIR / n).with_suffix(".md").read_text().splitlines()[0] for n in REFERENCE_MODELS]
    assert len(set(titles)) == len(titles), titles
    for file, title in zip(files, titles):
        assert f"`{Path(file).stem}`" in title
