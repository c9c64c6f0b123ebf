"""Where the contact is: the image's centroid and the contact model's position, weighted; either alone where
the other has none."""

from __future__ import annotations

import pytest

from tactile_manip.perception.contact import ContactState
from tactile_manip.perception.tactile_estimator import fused_position_mm, image_centroid_mm
from tactile_manip.perception.estimator import NO_CONTACT_FIELD
from tactile_manip.perception.pose import ISOTROPIC_REASON, angle_from_image
from tactile_manip.types import AngleEstimate

LINE = AngleEstimate(0.3, 0.9, True, centroid_mm=(2.0, -1.0), area_mm2=12.0)
TOUCH = ContactState(in_contact=True, x_mm=1.0, y_mm=1.0, x_sigma_mm=0.5, y_sigma_mm=0.5)


def test_both_estimates_are_weighted_by_the_images_share() -> None:
    assert fused_position_mm(LINE, TOUCH, 0.7) == pytest.approx((0.7 * 2.0 + 0.3 * 1.0, 0.7 * -1.0 + 0.3 * 1.0))
    assert fused_position_mm(LINE, TOUCH, 1.0) == pytest.approx((2.0, -1.0))
    assert fused_position_mm(LINE, TOUCH, 0.0) == pytest.approx((1.0, 1.0))


def test_no_position_where_the_field_is_below_the_pose_estimators_contact_rule() -> None:
    # a contact model trained on presses only says "in contact" on an empty pad; the field rule says not
    nothing = AngleEstimate(0.0, 0.0, False, reason=NO_CONTACT_FIELD)
    assert fused_position_mm(nothing, TOUCH, 0.5) is None


def test_a_head_angle_over_an_image_too_small_for_a_centroid_keeps_the_models_position() -> None:
    # the head defines the angle of a faint contact whose image holds 5 pixels: its centroid is no centroid
    head = AngleEstimate(0.4, 0.8, True, centroid_mm=(0.0, 0.0), area_mm2=5 * 0.01, source="head")
    assert image_centroid_mm(head, min_area_mm2=20 * 0.01) is None
    assert fused_position_mm(head, TOUCH, 0.5, min_area_mm2=20 * 0.01) == (1.0, 1.0)
    uniform = AngleEstimate(0.4, 0.8, True, area_mm2=0.0, source="head")  # nothing above the background
    assert fused_position_mm(uniform, TOUCH, 0.5) == (1.0, 1.0)


def test_either_alone_where_the_other_sees_no_contact() -> None:
    empty = AngleEstimate(0.0, 0.0, False, area_mm2=0.0, reason="empty contact")
    small = AngleEstimate(0.0, 0.0, False, area_mm2=0.1, reason="contact too small (3 px after filtering < 20)")
    assert fused_position_mm(empty, TOUCH, 0.7) == (1.0, 1.0)
    assert fused_position_mm(small, TOUCH, 0.7) == (1.0, 1.0)  # its centroid is no centroid
    lifted = ContactState(in_contact=False, x_mm=4.0, y_mm=4.0)
    assert fused_position_mm(LINE, lifted, 0.7) is None  # the contact model says no contact: no position
    force_only = ContactState(in_contact=True, force_n=3.0)
    assert fused_position_mm(LINE, force_only, 0.7) == (2.0, -1.0)
    assert fused_position_mm(empty, lifted, 0.7) is None


def test_an_isotropic_contact_has_no_angle_but_keeps_its_centroid() -> None:
    import numpy as np

    y, x = np.mgrid[:200, :200]
    disc = np.clip(1.0 - ((x - 130) ** 2 + (y - 100) ** 2) / 30.0 ** 2, 0, None)  # a round press right of centre
    est = angle_from_image(disc, pixel_mm=0.1)
    assert not est.defined and est.reason.startswith(ISOTROPIC_REASON)
    assert image_centroid_mm(est) == pytest.approx((3.05, -0.05), abs=0.01)
    assert fused_position_mm(est, TOUCH, 0.5) == pytest.approx(((3.05 + 1.0) / 2, (-0.05 + 1.0) / 2), abs=0.01)


def test_without_a_share_for_the_image_the_position_decodes_no_image() -> None:
    pytest.importorskip("onnxruntime")
    import numpy as np

    from tactile_manip.perception import TactilePoseEstimator, load_reconstructor
    from tactile_manip.perception.contact import ContactEstimator
    from tactile_manip.perception.tactile_estimator import TactileEstimator
    from tactile_manip.shipped import shipped_model
    from tactile_manip.sim.objects import IndenterPose
    from tactile_manip.sim.pair import SensorPair
    from tactile_manip.sim.shapes import make_indenter

    rec = load_reconstructor(shipped_model())
    runs = []
    run = rec._run
    rec._run = lambda fields: runs.append(len(fields)) or run(fields)
    rng = np.random.default_rng(0)
    fields = np.stack([SensorPair(seed=0).press(make_indenter("cylinder", size_mm=3.0), IndenterPose(x, 0.5, 0.2),
                                                10.0, rng, render_depth=False).field_ut for x in (-1.0, 1.5)])
    contact = ContactEstimator(shipped_model("contact"))
    model_only = TactileEstimator(TactilePoseEstimator(rec), contact, image_position_weight=0.0)
    for est in model_only.estimate_many(fields):
        assert est.position_mm == est.contact.position_mm
    assert runs == []  # the angles came from the head, the positions from the contact model: no image decoded
    fused = TactileEstimator(TactilePoseEstimator(rec), contact, image_position_weight=0.5).estimate_many(fields)
    assert fused[0].position_mm != fused[0].contact.position_mm and runs == [2]  # one batch for both pads
