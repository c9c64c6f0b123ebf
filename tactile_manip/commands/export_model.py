"""``tactile-manip export-model``: write a trained checkpoint as ONNX, checked against torch.

The model half of ``tactile-manip export`` on its own (``export --checkpoint`` does the same): an image model
(prior + decoder, with its metadata and an optional model card), a contact model, or an angle head attached to a
pose model (``--attach-to``), as the checkpoint's kind in :mod:`tactile_manip.learning.kinds` says. See
:mod:`tactile_manip.commands.export`.
"""

from __future__ import annotations

import argparse


def add_arguments(p: argparse.ArgumentParser) -> None:
    from tactile_manip.commands.export import add_model_arguments

    p.add_argument("--out", required=True, help="the .onnx file to write")
    p.add_argument("--force", action="store_true",
                   help="replace an earlier model export at --out (and --card); never a file export did not write")
    add_model_arguments(p, required=True)


def run(args: argparse.Namespace) -> int:
    from tactile_manip.commands.export import _export_checkpoint

    return _export_checkpoint(args)
