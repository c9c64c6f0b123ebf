"""The CVAE's taxel-map path: layout, geometry, and the error when the reading is missing."""

from __future__ import annotations

import pytest
from checks import TORCH_MISSING

torch = pytest.importorskip("torch", reason=TORCH_MISSING)

from tactile_manip.learning.cvae.model import SuperMagCVAE, mean_and_spread, preset, taxel_grid  # noqa: E402


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


# ---------------------------------------------------------------- decoder options (the faster decoder)


@pytest.mark.parametrize("overrides", [{"native_scale": 4, "head": "shuffle"}, {"native_scale": 2, "head": "shuffle"},
                                       {"native_scale": 4, "act": "relu", "dec_blocks": 0}])
def test_decoder_options_give_full_size_images_and_the_same_mean_without_the_variance(overrides):
    torch.manual_seed(0)
    cfg = preset("small", image_h=200, image_w=200, **overrides)
    model = SuperMagCVAE(cfg).eval()
    x = torch.randn(3, cfg.condition_size)
    z, e = torch.randn(3, cfg.latent), model.embed_dec(x)
    with torch.no_grad():
        mean, logvar = model.decoder(z, e, x)
        mean_only, none = model.decoder(z, e, x, with_logvar=False)
    assert mean.shape == logvar.shape == (3, 200, 200) and none is None
    torch.testing.assert_close(mean_only, mean)


def test_the_shuffle_head_places_each_native_pixel_over_its_own_block_of_output_pixels():
    """Through the decoder itself, on the trimmed path of the 200x200 scale-4 head (a 52x52 native grid, one
    native pixel too large on every side): with a head that copies channel 0 of the last feature map to the
    mean's 16 sub-pixels, the mean is that map upsampled by repetition (4x4 blocks), centred on the image."""
    torch.manual_seed(0)
    cfg = preset("small", image_h=200, image_w=200, native_scale=4, head="shuffle")
    decoder = SuperMagCVAE(cfg).eval().decoder
    assert decoder._trim  # the unpadded head: 50x50 of the 52x52 grid, shuffled to exactly 200x200
    with torch.no_grad():
        decoder.head.weight.zero_()
        decoder.head.bias.zero_()
        decoder.head.weight[:16, 0, 1, 1] = 1.0
        for mod in decoder.mod:  # an input-dependent feature map (the zero-initialised modulation is not)
            torch.nn.init.normal_(mod.proj.weight, std=1.0)
    features = []
    hook = decoder.ups[-1].register_forward_hook(lambda module, args, out: features.append(out))
    z, e, x = torch.randn(2, cfg.latent), torch.randn(2, cfg.embed), torch.rand(2, cfg.condition_size) * 2 - 1
    with torch.no_grad():
        mean, logvar = decoder(z, e, x)
        mean_only, _ = decoder(z, e, x, with_logvar=False)
    hook.remove()
    torch.testing.assert_close(features[1], features[0])
    feat = features[0][:, 0]                            # (2, 52, 52): the last feature map, channel 0
    assert feat.shape == (2, 52, 52) and mean.shape == logvar.shape == (2, 200, 200)
    expected = torch.relu(feat.repeat_interleave(4, 1).repeat_interleave(4, 2)[:, 4:204, 4:204])
    assert (expected > 0).any() and (expected == 0).any()  # both signs reach the ReLU
    torch.testing.assert_close(mean, expected)
    torch.testing.assert_close(mean_only, expected)
    torch.testing.assert_close(logvar, torch.zeros_like(logvar))  # the log-variance channels are all zero


def test_decoder_options_are_validated():
    with pytest.raises(ValueError, match="head"):
        preset("compact", head="nearest")
    with pytest.raises(ValueError, match="act"):
        preset("compact", act="tanh")


def test_a_training_config_decoder_table_overrides_the_preset(tmp_path):
    from tactile_manip.learning.cvae.train import architecture, load_train_config

    path = tmp_path / "fast.toml"
    path.write_text('preset = "compact"\n\n[decoder]\nnative_scale = 4\nchannels = [24, 12, 6]\nhead = "shuffle"\n'
                    'act = "relu"\ndec_blocks = 0\n')
    cfg = architecture(load_train_config(path))
    assert (cfg.native_scale, cfg.channels, cfg.head, cfg.act, cfg.dec_blocks) == (4, (24, 12, 6), "shuffle", "relu", 0)
    assert cfg.spatial == preset("compact").spatial  # what the table does not name stays the preset's
    plain = tmp_path / "plain.toml"
    plain.write_text('preset = "compact"\n')
    assert architecture(load_train_config(plain)) == preset("compact")
    path.write_text('preset = "compact"\n\n[decoder]\nhead = "nearest"\n')
    with pytest.raises(ValueError, match="head"):  # CVAEConfig refuses it when the architecture is built
        architecture(load_train_config(path))
    path.write_text('preset = "compact"\n\n[decoder]\nnative_scale = -1\n')
    with pytest.raises(ValueError, match="native_scale"):  # ConfigError is a ValueError
        load_train_config(path)


def test_an_untrained_export_of_a_training_config_runs_on_onnxruntime(tmp_path):
    pytest.importorskip("onnx")
    pytest.importorskip("onnxruntime")
    import numpy as np

    from tactile_manip.learning.cvae.eager import export_untrained
    from tactile_manip.perception.reconstruct import load_reconstructor

    config = tmp_path / "tiny_fast.toml"
    config.write_text('preset = "small"\n\n[decoder]\nnative_scale = 4\nhead = "shuffle"\nact = "relu"\n')
    path = export_untrained(str(config), tmp_path / "out")
    assert path.name == "tiny_fast.onnx"
    rec = load_reconstructor(path, threads=1)
    depth = rec.reconstruct(np.random.default_rng(0).normal(0.0, 100.0, (4, 4, 3))).depth_mm
    assert depth.shape == (200, 200) and np.isfinite(depth).all()


@pytest.mark.parametrize("image_hw, trims", [((36, 36), True), ((40, 40), False), ((36, 38), False)])
def test_the_shuffle_heads_unpadded_convolution_keeps_exactly_the_centre_crop(image_hw, trims):
    """A native grid one pixel too large on every side: the unpadded head equals the padded head then cropped,
    for the training output (mean and log-variance) and for the mean alone."""
    from tactile_manip.learning.cvae.model import CVAEConfig

    torch.manual_seed(0)
    cfg = preset("small", image_h=image_hw[0], image_w=image_hw[1])
    cfg = CVAEConfig(**{**cfg.__dict__, "native_scale": 2, "head": "shuffle"})
    decoder = SuperMagCVAE(cfg).eval().decoder
    with torch.no_grad():
        torch.nn.init.normal_(decoder.head.weight, std=0.5)  # both signs: the ReLU and the clamp matter
        for mod in decoder.mod:
            torch.nn.init.normal_(mod.proj.weight, std=1.0)
    assert decoder._trim is trims
    z, e, x = torch.randn(3, cfg.latent), torch.randn(3, cfg.embed), torch.rand(3, 48) * 2 - 1
    with torch.no_grad():
        mean, logvar = decoder(z, e, x)
        mean_only, none = decoder(z, e, x, with_logvar=False)
        decoder._trim = False  # the reference: padded head, shuffle, centre crop
        ref_mean, ref_logvar = decoder(z, e, x)
    assert none is None and mean.shape == (3, *image_hw) and (mean > 0).any() and (mean == 0).any()
    torch.testing.assert_close(mean, ref_mean, rtol=0, atol=1e-6)
    torch.testing.assert_close(logvar, ref_logvar, rtol=0, atol=1e-6)
    torch.testing.assert_close(mean_only, mean, rtol=0, atol=1e-6)
