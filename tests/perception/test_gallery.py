"""The evaluation gallery: one depth colour bar for every panel, and no untrained model in it."""

from __future__ import annotations

import pytest

from tactile_manip.evaluation.images import gallery, gallery_figure, untrained
from tactile_manip.perception.reconstruct import OnnxReconstructor, load_reconstructor

pytest.importorskip("onnxruntime")


def test_exported_metadata_records_the_epochs_trained(onnx_4x4) -> None:
    assert onnx_4x4.metadata["training"]["epochs_run"] == 0  # the fixture exports untrained weights
    assert untrained(OnnxReconstructor(onnx_4x4.path))
    assert not untrained(load_reconstructor("bilinear"))


def test_gallery_has_a_depth_colour_bar_and_leaves_untrained_models_out(onnx_4x4, data_4x4, tmp_path) -> None:
    bilinear = load_reconstructor("bilinear", output_px=40)
    fresh, trained = OnnxReconstructor(onnx_4x4.path), OnnxReconstructor(onnx_4x4.path)
    trained.metadata = {**trained.metadata, "training": {"epochs_run": 3}}
    rows = [("train", 0), ("test", 5)]
    fig, skipped = gallery_figure(data_4x4, {"Bilinear": bilinear, "Fresh": fresh, "Trained": trained}, rows)
    assert skipped == ["Fresh"]
    bars = [ax for ax in fig.axes if ax.get_label() == "<colorbar>"]
    panels = [ax for ax in fig.axes if ax.images]
    assert [ax.get_title() for ax in panels[:3]] == ["ground truth (VBTS)", "Bilinear", "Trained"]
    assert len(panels) == 3 * len(rows)
    assert len(bars) == 1 and "depth [mm]" in bars[0].get_ylabel()
    assert {ax.images[0].get_clim() for ax in panels} == {(0.0, 2.0)}  # one scale, the bar's
    assert gallery(tmp_path / "g.png", data_4x4, {"Fresh": fresh, "Trained": trained}, rows) == ["Fresh"]
    assert (tmp_path / "g.png").stat().st_size > 0

