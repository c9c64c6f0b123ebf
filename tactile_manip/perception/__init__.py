"""Perception, the runtime (readings -> estimates): reconstructors (ONNX model and interpolation baselines), pose.

The pose API users plug into their tasks::

    from tactile_manip.perception import TactilePoseEstimator, load_reconstructor
    estimator = TactilePoseEstimator(load_reconstructor("models/supermag.onnx"))
    estimate = estimator.estimate(field_ut)     # (4, 4, 3) uT -> AngleEstimate

and the contact API (``tactile_manip.perception.contact``; docs/contact_model.md)::

    contact = ContactEstimator("models/contact.onnx")
    state = contact.estimate(field_ut)          # (R, C, 3) uT -> ContactState: position, force, sigmas

(numpy and scipy at import; onnxruntime only when an ONNX model is loaded.) Scoring these on datasets (image
metrics, Table I, contact evaluation, the reference pose pipeline) is :mod:`tactile_manip.evaluation`.
"""

from tactile_manip.perception.contact import ContactEstimator, ContactState
from tactile_manip.perception.estimator import StreamStats, TactilePoseEstimator
from tactile_manip.perception.pose import PoseParams, angle_from_image, wrap_axial
from tactile_manip.perception.reconstruct import Reconstructor, load_reconstructor

__all__ = ["ContactEstimator", "ContactState", "PoseParams", "Reconstructor", "StreamStats", "TactilePoseEstimator",
           "angle_from_image", "load_reconstructor", "wrap_axial"]
