"""A model card (markdown) for an exported model: what it is, how it was trained, what it scores."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any


def model_card(meta: dict[str, Any], history: dict[str, Any], *, name: str = "", table_md: str = "",
               machine: str = "", commands: list[str] | None = None, latency: str = "") -> str:
    """Markdown text of the card from the export metadata, the training history and the evaluation table.

    ``name`` (the model file's stem) heads the card, so that the cards of several models tell themselves apart.
    """
    tc, mc = meta["train_config"], meta["model_config"]
    last = history["history"][-1]
    data = meta.get("training_data", {})
    inp, out = meta["input"], meta["output"]
    channels = inp.get("channels", {"names": ["x", "y", "z"], "kind": "magnetic_vector", "unit": "uT"})
    image_unit = out.get("image", {}).get("unit", "mm")
    magnetic = channels["kind"] == "magnetic_vector" and channels["unit"] == "uT"
    reading = (f"magnetic reading ({mc['taxel_rows']}x{mc['taxel_cols']} chips, 3 axes, microtesla, "
               "baseline-subtracted)" if magnetic else
               f"reading of {mc['taxel_rows']}x{mc['taxel_cols']} taxels x {len(channels['names'])} "
               f"{channels['kind']} channels ({', '.join(channels['names'])}) in {channels['unit']}")
    image = ("depth image (" + (f"{out['pixel_mm']} mm/px, " if out.get("pixel_mm") else "") + "mm of indentation)"
             if image_unit == "mm" else f"image in {image_unit}")
    scaling = (f"clamped to +-{inp['clamp_ut']} uT and scaled to [-1, 1] inside the graph" if not inp.get("offset")
               else f"normalised per channel by the training split, clamped to +-{inp['clamp_std']} standard "
                    "deviations and scaled to [-1, 1] inside the graph")
    # datasets written by `simulate` before it recorded its name in the provenance carry no source
    source = ("simulated pairs" if data.get("source") is None or str(data["source"]).endswith("simulate")
              else f"pairs ({data['source']})")
    lines = [
        f"# {'`' + name + '`: ' if name else ''}SuperMag CVAE, `{meta['preset']}` preset",
        "",
        f"Super-resolves one {reading} into a {mc['image_h']}x{mc['image_w']} {image}. "
        "Conditional VAE after SuperMag (IROS 2025); only the conditional prior and the decoder are in the "
        "ONNX file. Load it with `tactile_manip.perception.reconstruct.load_reconstructor(PATH)`.",
        "",
        "## Inputs and outputs",
        f"- `field_ut` (B, {mc['taxel_rows']}, {mc['taxel_cols']}, {len(channels['names'])}) float32: "
        f"{inp['layout']}; {inp['units']}; channels used: {inp['axes_used']}; {scaling}.",
        f"- `eps` (B, K, {mc['latent']}) float32: prior samples; zeros with K = 1 give the prior mean.",
        f"- `depth_mm`, `spread_mm` (B, {mc['image_h']}, {mc['image_w']}) float32: mean and spread over the K "
        f"samples, in {image_unit}.",
        "",
        "## Training",
        f"- Data: {data.get('pairs', '?')} {source} ({', '.join(data.get('objects', []))}), fingerprint "
        f"`{meta['data_fingerprint']}`; trained on the `train` split of "
        f"{', '.join(tc['objects']) or ', '.join(data.get('objects_with_train_split', [])) or 'every object'}.",
        f"- Recipe: AdamW lr {tc['lr']} ({tc['lr_schedule']} to {tc['lr_min']}), weight decay "
        f"{tc['weight_decay']}, batch {tc['batch_size']}, {tc['epochs']} epochs, negative ELBO with beta-NLL "
        f"(beta {tc['nll_beta']}) plus the prior-path term (weight {tc['prior_weight']}), symmetry augmentation "
        f"{'on' if tc['augment'] else 'off'}, seed {tc['seed']}.",
        f"- Architecture: {meta['parameters']:,} inference parameters; latent {mc['latent']}; decoder channels "
        f"{mc['channels']}; taxel-map path {mc.get('spatial', 0) or 'off'}; full config in the file's metadata.",
        f"- Ran {history['epochs_run']} epochs in {history['train_seconds'] / 60:.1f} min with "
        f"{history['threads']} torch threads{(' on ' + machine) if machine else ''}; best validation PSNR "
        f"{history['best_val_psnr']:.2f} dB at epoch {history['best_epoch']} (last epoch: "
        f"{last['val_psnr']:.2f} dB).",
        "",
    ]
    if table_md:
        rng = data.get("image", {})
        span = f"{rng['data_range']:g} {rng['unit']}" if rng else "2 mm"
        lines += [f"## Table I on unseen objects (test split, PSNR/SSIM data range {span})", "", table_md.strip(), ""]
    if commands:
        lines += ["## Reproduce", "", "```bash", *commands, "```", ""]
    limits = ("Trained on simulated data of one default sensor pair (see docs/simulator.md). A real sensor needs "
              "its own paired data in the same dataset format, trained with the same commands."
              if source == "simulated pairs" else
              f"Trained on the {data.get('pairs', '?')} pairs of one dataset ({data.get('source')}); it knows only "
              "that sensor and those contacts.")
    lines += ["## Limits", "", limits, ""]
    if latency:
        lines += ["## Speed (onnxruntime, one reading)", "", latency.strip(), ""]
    return "\n".join(lines)


def write_model_card(path: str | Path, meta: dict[str, Any], history_path: str | Path, **kwargs: Any) -> Path:
    history = json.loads(Path(history_path).read_text())
    Path(path).write_text(model_card(meta, history, **kwargs))
    return Path(path)
