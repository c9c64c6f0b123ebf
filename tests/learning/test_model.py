"""The CVAE's taxel-map path: layout, geometry, and the error when the reading is missing."""

from __future__ import annotations

import pytest

torch = pytest.importorskip("torch")

from tactile_manip.learning.model import SuperMagCVAE, mean_and_spread, preset, taxel_grid  # noqa: E402


def test_taxel_grid_puts_each_reading_value_at_its_row_column_and_axis():
    cfg = preset("compact", taxel_rows=4, taxel_cols=5, axes=3)
    reading = torch.arange(2 * 4 * 5 * 3, dtype=torch.float32).view(2, 4, 5, 3)
    grid = taxel_grid(reading.flatten(1), cfg)
    assert grid.shape == (2, 3, 4, 5)
    for r, c, a in [(0, 0, 0), (1, 4, 2), (3, 2, 1)]:
        assert grid[1, a, r, c] == reading[1, r, c, a]


def test_a_taxel_feature_lands_over_its_own_patch_of_the_pad():
    """A signal on one taxel, passed through a pass-through taxel map, peaks over that taxel's cell."""
    cfg = preset("small", axes=1, image_h=80, image_w=80)
    model = SuperMagCVAE(cfg)
    decoder = model.decoder
    with torch.no_grad():  # both convolutions pass the reading through on channel 0, the rest stay 0
        for conv in (decoder.taxel_map[0], decoder.taxel_map[2]):
            conv.weight.zero_()
            conv.bias.zero_()
            conv.weight[0, 0, 1, 1] = 1.0
    x = torch.zeros(1, 16)
    x[0, 1 * 4 + 2] = 1.0  # row 1, column 2
    captured = {}
    decoder.base.register_forward_pre_hook(lambda mod, inp: captured.update(input=inp[0]))
    with torch.no_grad():
        # the stem's channels come first, then the taxel map's
        decoder(torch.zeros(1, cfg.latent), torch.zeros(1, cfg.embed), x)
    m = captured["input"][0, -cfg.spatial]
    bh, bw = cfg.base_hw
    row, col = divmod(int(m.argmax()), bw)
    cell = (int((row + 0.5) * 4 / bh), int((col + 0.5) * 4 / bw))  # the pad cell under the peak
    assert cell == (1, 2)


def test_decoder_with_a_taxel_map_refuses_to_run_without_the_reading():
    cfg = preset("small", image_h=24, image_w=24)
    model = SuperMagCVAE(cfg)
    with pytest.raises(ValueError, match="taxel-map path"):
        model.decoder(torch.zeros(1, cfg.latent), torch.zeros(1, cfg.embed))


def test_paper_preset_keeps_the_published_design_without_a_taxel_map():
    assert preset("paper").spatial == 0 and SuperMagCVAE(preset("paper", image_h=24, image_w=24)).decoder.taxel_map is None
    with pytest.raises(ValueError, match="spatial"):
        preset("compact", spatial=-1)


@pytest.mark.parametrize("k", [1, 3])
def test_mean_and_spread_match_torch_mean_and_std(k):
    samples = torch.rand(2, k, 7, 5, dtype=torch.float64)
    mean, spread = mean_and_spread(samples)
    torch.testing.assert_close(mean, samples.mean(1))
    torch.testing.assert_close(spread, samples.std(1, unbiased=False))


def test_inference_decoder_gives_the_training_mean_without_the_variance_channel():
    cfg = preset("small", image_h=24, image_w=24)
    model = SuperMagCVAE(cfg).eval()
    z, e, x = torch.randn(3, cfg.latent), torch.randn(3, cfg.embed), torch.rand(3, cfg.condition_size) * 2 - 1
    with torch.no_grad():
        full_mean, logvar = model.decoder(z, e, x)
        mean, none = model.decoder(z, e, x, with_logvar=False)
    assert none is None and logvar.shape == mean.shape
    torch.testing.assert_close(mean, full_mean)
