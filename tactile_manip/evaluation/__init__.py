"""Evaluation: scoring the models and the runtime of :mod:`tactile_manip.perception` on datasets.

- :mod:`.metrics`: image quality metrics for depth images (PSNR and SSIM at a stated data range, FD-DCT);
- :mod:`.images`: Table I of the image models (PSNR/SSIM/FD-DCT per method, rod angle errors, the gallery);
- :mod:`.contact`: evaluation of contact models on labelled presses, against the baselines of
  :mod:`.contact_baselines` (Linear, kNN, MLP; scikit-learn only when installed);
- :mod:`.pose_reference`: the slow reference pose pipeline that the fast one is checked against.

The runtime (``tactile_manip.perception``) never imports this layer. Importing the package imports none of
its modules; each is numpy and scipy at import (matplotlib and scikit-learn only inside the functions that
draw a figure or fit a baseline).
"""
