"""The DTact depth pipeline and the paper's alignment: geometry, bad input, references, and the full pipeline
against the simulator's ground truth."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from tactile_manip.errors import CalibrationError
from tactile_manip.collection.camera_sim import DEFAULT_CORNERS_PX
from tactile_manip.collection.vbts import (
    DepthParams,
    DepthPipeline,
    PadAlignment,
    apply_homography,
    homography_from_points,
    mirror_image,
    resize_area,
    to_grey,
)
from tactile_manip.collection.vbts_calibration import check_reference_clear
from tactile_manip.sim.objects import IndenterPose
from tactile_manip.sim.shapes import make_indenter

ALIGN = PadAlignment(corners_px=DEFAULT_CORNERS_PX, camera_shape=(480, 640))


def test_homography_maps_the_pad_corners_and_back():
    src = np.array([(-10.5, 10.5), (10.5, 10.5), (10.5, -10.5), (-10.5, -10.5)])
    h = homography_from_points(src, DEFAULT_CORNERS_PX)
    u, v = apply_homography(h, src[:, 0], src[:, 1])
    assert np.allclose(np.stack([u, v], 1), DEFAULT_CORNERS_PX, atol=1e-9)
    x, y = apply_homography(np.linalg.inv(h), u, v)
    assert np.allclose(np.stack([x, y], 1), src, atol=1e-9)
    with pytest.raises(ValueError, match="degenerate"):
        homography_from_points(src, [(0, 0), (1, 1), (2, 2), (3, 3)])


def test_area_resize_keeps_the_mean_and_constants():
    img = np.random.default_rng(0).random((325, 325))
    out = resize_area(img, (200, 200))
    assert out.shape == (200, 200) and out.dtype == np.float32
    assert abs(out.mean() - img.mean()) < 1e-6
    assert np.allclose(resize_area(np.full((325, 325), 1.7), (200, 200)), 1.7)
    with pytest.raises(ValueError, match="2-D"):
        resize_area(np.zeros((3, 4, 5)), (2, 2))


def test_mirror_flips_one_pad_axis_and_is_its_own_inverse():
    img = np.arange(12.0).reshape(3, 4)
    assert np.array_equal(mirror_image(img, "x"), img[:, ::-1])
    assert np.array_equal(mirror_image(img, "y"), img[::-1])
    assert np.array_equal(mirror_image(mirror_image(img, "x"), "x"), img)
    with pytest.raises(ValueError, match="mirror"):
        mirror_image(img, "z")


def test_the_crop_is_325_px_of_20_mm_and_the_output_200_px_of_0_1_mm():
    assert ALIGN.raw_px == 325 and ALIGN.out_px == 200
    assert ALIGN.out_pixel_mm == pytest.approx(0.1)
    assert ALIGN.rectify(np.zeros((480, 640), np.float32)).shape == (325, 325)


@pytest.mark.parametrize("change, match", [
    ({"corners_px": ((0, 0), (1, 1), (2, 2))}, "4 finite"),
    ({"camera_shape": (100, 100)}, "outside the 100x100 camera image"),
    ({"mirror": "z"}, "mirror"),
    ({"crop_mm": 22.0}, "leaves the 21.0 mm pad"),
    ({"raw_px": 1}, "raw_px"),
])
def test_alignment_refuses_bad_geometry(change, match):
    with pytest.raises(ValueError, match=match):
        dataclasses.replace(ALIGN, **change)


def test_bad_images_get_clear_errors(calibration, reference_frames):
    pipe = calibration.pipeline()
    with pytest.raises(ValueError, match="uint8"):
        pipe.depth(reference_frames[0].astype(np.float32))
    with pytest.raises(ValueError, match=r"shape \(H, W\) or \(H, W, 3\)"):
        pipe.depth(np.zeros((480, 640, 4), np.uint8))
    with pytest.raises(ValueError, match="does not match the calibration's"):
        pipe.depth(np.zeros((240, 320), np.uint8))
    fresh = DepthPipeline(calibration.alignment, calibration.table_levels, calibration.table_mm)
    with pytest.raises(CalibrationError, match="no reference"):
        fresh.depth(reference_frames[0])


def test_bgr_frames_are_converted_like_opencv():
    bgr = np.zeros((2, 2, 3), np.uint8)
    bgr[..., 0], bgr[..., 1], bgr[..., 2] = 10, 100, 200
    assert to_grey(bgr)[0, 0] == pytest.approx(0.114 * 10 + 0.587 * 100 + 0.299 * 200, abs=1e-3)


def test_lookup_table_and_params_are_validated():
    with pytest.raises(ValueError, match="strictly increasing"):
        DepthPipeline(ALIGN, [0, 2, 1], [0, 1, 2])
    with pytest.raises(ValueError, match="must not decrease"):
        DepthPipeline(ALIGN, [0, 1, 2], [0, 1, 0.5])
    with pytest.raises(ValueError, match="blur_mm"):
        DepthParams(blur_mm=-1.0)


def test_a_reference_taken_while_the_contact_changes_is_refused(calibration, sim_camera, render):
    rng = np.random.default_rng(3)
    frames = render(sim_camera, 5, rng)
    sim_camera.set_contact(make_indenter("letter_r"), IndenterPose(), 10.0)
    frames += render(sim_camera, 5, rng)
    sim_camera.clear_contact()
    with pytest.raises(CalibrationError, match="changed while the reference was taken"):
        calibration.pipeline().set_reference(frames)
    with pytest.raises(CalibrationError, match="at least 2"):
        calibration.pipeline().set_reference(frames[:1])


def test_a_reference_taken_under_a_still_contact_is_refused(calibration, sim_camera, render):
    rng = np.random.default_rng(4)
    sim_camera.set_contact(make_indenter("allen_key"), IndenterPose(x_mm=1.0), 10.0)
    frames = render(sim_camera, 8, rng)
    sim_camera.clear_contact()
    pipe = calibration.pipeline()
    reference = pipe.set_reference(frames)  # steady, so the frames alone cannot tell
    with pytest.raises(CalibrationError, match="looks pressed"):
        check_reference_clear(reference, calibration.reference, pixel_mm=calibration.alignment.raw_pixel_mm)


def test_a_clear_reference_passes_even_under_a_lighting_change(calibration, sim_camera, render):
    frames = [np.clip(f.astype(np.int16) - 6, 0, 255).astype(np.uint8)   # the LEDs dimmed by 6 levels
              for f in render(sim_camera, 8, np.random.default_rng(5))]
    reference = calibration.pipeline().set_reference(frames)
    check_reference_clear(reference, calibration.reference, pixel_mm=calibration.alignment.raw_pixel_mm)


# The full pipeline (calibrated from the ball press) against the simulator's ground truth. Figures printed
# with `pytest tests/collection/test_vbts_pipeline.py -k ground_truth -s`.
CASES = [("allen_key", IndenterPose(x_mm=1.0, y_mm=-0.5, yaw_rad=0.4), 10.5),
         ("letter_r", IndenterPose(x_mm=-1.5, y_mm=1.0, yaw_rad=-0.7), 10.0),
         ("hex_bar", IndenterPose(x_mm=0.5, yaw_rad=1.1), 10.8)]


@pytest.mark.parametrize("name, pose, force", CASES, ids=[c[0] for c in CASES])
def test_full_pipeline_matches_the_simulators_ground_truth(calibration, sim_camera, name, pose, force):
    obj = make_indenter(name)
    sim_camera.set_contact(obj, pose, force)
    frame = sim_camera.render(0.0, np.random.default_rng(6))
    sim_camera.clear_contact()
    depth = calibration.pipeline().depth(frame)
    truth = sim_camera.pair.press(obj, pose, force, np.random.default_rng(7))
    imprint, sim_depth = truth.imprint_mm, truth.depth_mm
    contact = imprint > 0
    rmse_imprint = float(np.sqrt(np.mean((depth - imprint) ** 2)))
    rmse_contact = float(np.sqrt(np.mean((depth - imprint)[contact] ** 2)))
    rmse_sim = float(np.sqrt(np.mean((depth - sim_depth) ** 2)))
    peak = abs(float(depth.max()) - float(imprint.max()))
    print(f"\n{name}: pipeline vs imprint RMSE {rmse_imprint:.4f} mm (in contact {rmse_contact:.4f} mm), "
          f"vs the simulator's DTact depth {rmse_sim:.4f} mm, peak error {peak:.3f} mm")
    assert depth.shape == (200, 200) and depth.dtype == np.float32 and depth.min() >= 0
    assert rmse_sim < 0.015           # the same DTact artefacts as the simulator's VBTS model
    assert rmse_imprint < 0.07        # the rest is DTact's smoothing of sharp edges (the "R" has 2 mm walls)
    assert peak < 0.05
    wrong = calibration.pipeline()
    wrong.alignment = dataclasses.replace(calibration.alignment, mirror="none")
    assert float(np.sqrt(np.mean((wrong.depth(frame) - imprint) ** 2))) > 2 * rmse_imprint  # the mirror matters
