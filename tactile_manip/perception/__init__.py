"""Perception, the runtime (readings -> estimates).

The one object users, behaviours and trial cells take is
:class:`~tactile_manip.perception.tactile_estimator.TactileEstimator` (also ``from tactile_manip import
TactileEstimator``)::

    from tactile_manip.perception import TactileEstimator
    estimator = TactileEstimator.load()         # the shipped pose and contact models, from any folder
    est = estimator.estimate(field_ut)          # (4, 4, 3) uT -> TactileEstimate: angle, contact, position_mm
    est = estimator.read(sensor, frames=4)      # or stream(sensor): from a live TactileSensor

Its parts: the pose part (:class:`TactilePoseEstimator`: a reconstructor, the ONNX model or an interpolation
baseline, and the pose pipeline; or the blind baseline, :mod:`~tactile_manip.perception.baselines`) and the
contact model (:class:`ContactEstimator`, docs/contact_model.md). :class:`Estimator` states the interface.

(numpy and scipy at import; onnxruntime only when an ONNX model is loaded.) Scoring these on datasets (image
metrics, Table I, contact evaluation, the reference pose pipeline) is :mod:`tactile_manip.evaluation`.
"""

from tactile_manip.perception.contact import ContactEstimator, ContactState
from tactile_manip.perception.estimator import TactilePoseEstimator
from tactile_manip.perception.pose import PoseParams, angle_from_image, wrap_axial
from tactile_manip.perception.reconstruct import Reconstructor, load_reconstructor
from tactile_manip.perception.tactile_estimator import Estimator, StreamStats, TactileEstimate, TactileEstimator

__all__ = ["ContactEstimator", "ContactState", "Estimator", "PoseParams", "Reconstructor", "StreamStats",
           "TactileEstimate", "TactileEstimator", "TactilePoseEstimator", "angle_from_image", "load_reconstructor",
           "wrap_axial"]
