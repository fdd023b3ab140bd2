"""Large images in row tiles: ``correct`` tile by tile equals the untiled path.

The one-pass correction (frames → ``ln c`` with the balance folded into
``g`` → ``l = exp(ln c) / (u·v)``) is checked against the float64 reference
(the per-pixel merge of the denoised means, then ``exp / (u·v)`` in
float64) within the float32 bound, and tiles, threads and a camera loaded
from disk change no bit of it.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from photoquant.balance import BalanceModel
from photoquant.correction import correct
from photoquant.merge import MergeModel, merge_Debevec1997
from photoquant.model import CameraModel, load_camera
from photoquant.response.model import ResponseModel
from photoquant.sensor_lut import SensorLUTModel
from photoquant.stack import ExposureStack
from photoquant.vignetting import ExtendedGoldmanChenVignetting
from pqsim.synth_camera.presets import camera_from_preset

from .analytic import capture, log_uniform_scene, true_g

BALANCE = (0.85, 1.0, 0.75)
EXPOSURES = np.geomspace(0.5, 500.0, 6)
LEVELS = np.arange(256.0)
EPS = 2.0**-24


def _model(shape, rng, merge=None) -> CameraModel:
    g = np.stack([true_g(np.maximum(LEVELS, 0.5), ch, balance=BALANCE) for ch in range(3)])
    response = ResponseModel(
        "Debevec 1997", LEVELS, g, np.round(np.array(BALANCE) * 255), valid_min=np.full(3, 2.0)
    )
    params = np.asarray(camera_from_preset("ccd").vignetting_params, dtype=float)
    return CameraModel(
        image_shape=shape,
        channels=("R", "G", "B"),
        bit_depth=8,
        response=response,
        merge=merge or MergeModel("Debevec 1997", {"weighting": "hat-quantisation"}),
        balance=BalanceModel("White Chart", np.array([1.2, 1.0, 0.8])),
        sensor_lut=SensorLUTModel("Irradiance Scene", rng.uniform(0.9, 1.1, (*shape, 3))),
        vignetting=ExtendedGoldmanChenVignetting("Extended Goldman-Chen", params),
    )


def _stack(rng, shape, n_repeats) -> ExposureStack:
    l = log_uniform_scene(rng, (*shape, 3), decades=4.0)
    frames = capture(l, EXPOSURES, balance=BALANCE, noise_dn=1.5, n_repeats=n_repeats, rng=rng)
    return ExposureStack(frames, EXPOSURES, saturation_level=np.round(np.array(BALANCE) * 255))


def _reference(stack: ExposureStack, model: CameraModel) -> tuple[np.ndarray, np.ndarray]:
    """float64: eq. 6 per pixel on the means with the stack's masks, then exp / (u·v)."""
    resp = model.balanced_response()
    ref = merge_Debevec1997(
        stack.mean(),
        stack.exposure_s,
        resp.levels,
        resp.log_inverse_response,
        saturation_level=resp.saturation_level,
        saturated=stack.saturated(resp.saturation_level),
        dark_clipped=stack.dark_clipped(),
        min_level=resp.valid_min,
        weighting="hat-quantisation",
        c_min=np.asarray(resp.black_level, dtype=float),
    )
    l = np.exp(ref.log_photoquantity) / (model.sensor_lut.lut * model.vignetting_map())
    return l, ref.mask


@pytest.mark.parametrize("n_repeats", [1, 3])
def test_one_pass_correction_equals_the_float64_reference(rng, n_repeats):
    shape = (9, 11)
    model, stack = _model(shape, rng), _stack(rng, shape, n_repeats)
    out = correct(stack, model, refine_exposures=False)
    l_ref, mask_ref = _reference(stack, model)
    np.testing.assert_array_equal(out.mask, mask_ref)
    assert out.photoquantity.dtype == np.float32
    # |Δ ln c| <= (2K + 3)·ε·max|g − ln t| (the merge), then exp, the float32 gain and
    # the product: a few ε more
    resp = model.balanced_response()
    m = np.max(np.abs(resp.log_inverse_response[..., None] - np.log(EXPOSURES)))
    rtol = (2 * EXPOSURES.size + 3) * EPS * m + 6 * EPS
    ok = ~mask_ref
    np.testing.assert_allclose(out.photoquantity[ok], l_ref[ok], rtol=rtol, atol=0)
    assert np.isnan(out.photoquantity[~ok]).all()


@pytest.mark.parametrize("n_repeats", [1, 2])
@pytest.mark.parametrize(("tile_rows", "workers"), [(1, 1), (2, 3), (4, 2)])
def test_tiles_and_threads_change_no_bit_of_the_correction(rng, n_repeats, tile_rows, workers):
    shape = (7, 5)
    model, stack = _model(shape, rng), _stack(rng, shape, n_repeats)
    whole = correct(stack, model, refine_exposures=False, tile_rows=10**6, workers=1)
    tiled = correct(stack, model, refine_exposures=False, tile_rows=tile_rows, workers=workers)
    for field in ("photoquantity", "mask", "all_saturated", "all_dark"):
        np.testing.assert_array_equal(getattr(tiled, field), getattr(whole, field), err_msg=field)


def test_a_camera_loaded_from_disk_corrects_in_tiles_as_it_does_whole(rng, tmp_path):
    shape = (8, 6)
    model, stack = _model(shape, rng), _stack(rng, shape, 1)
    model.save(tmp_path / "camera")
    loaded = load_camera(tmp_path / "camera")
    whole = correct(stack, loaded, refine_exposures=False, tile_rows=10**6)
    tiled = correct(stack, loaded, refine_exposures=False, tile_rows=3)
    np.testing.assert_array_equal(tiled.photoquantity, whole.photoquantity)
    # and as the camera it was saved from: its maps went through float32 files
    mem = correct(stack, model, refine_exposures=False)
    np.testing.assert_array_equal(mem.mask, tiled.mask)
    ok = ~mem.mask
    np.testing.assert_allclose(tiled.photoquantity[ok], mem.photoquantity[ok], rtol=4 * EPS)


def test_a_whole_image_merge_method_still_corrects(rng):
    shape = (6, 7)
    model = _model(shape, rng, merge=MergeModel("Robertson 2003"))
    stack = _stack(rng, shape, 1)
    assert model.merge.tile_plan(stack, model.balanced_response()) is None
    out = correct(stack, model, refine_exposures=False, tile_rows=2)
    assert out.photoquantity.dtype == np.float32 and out.photoquantity.shape == (*shape, 3)
    assert np.isfinite(out.photoquantity[~out.mask]).all()


@pytest.mark.parametrize("layout", ["C", "F", "view"])
@pytest.mark.parametrize(("tile_rows", "workers"), [(1, 1), (3, 2)])
def test_merge_tiles_read_any_layout_alike(rng, layout, tile_rows, workers):
    # a C-contiguous stack is read whole at each tile's offset, any other layout tile by
    # tile copied: the same bits as the whole image in one tile
    frames = capture(log_uniform_scene(rng, (9, 6, 3)), EXPOSURES, balance=BALANCE)[0]
    g = np.stack([true_g(np.maximum(LEVELS, 0.5), ch, balance=BALANCE) for ch in range(3)])
    whole = merge_Debevec1997(frames, EXPOSURES, LEVELS, g, tile_rows=10**6, workers=1)
    if layout == "F":
        values = np.asfortranarray(frames)
    elif layout == "view":
        values = np.concatenate([frames, frames], axis=2)[:, :, ::2]  # strided columns
        values[:] = frames
    else:
        values = frames
    tiled = merge_Debevec1997(values, EXPOSURES, LEVELS, g, tile_rows=tile_rows, workers=workers)
    for name in ("log_photoquantity", "weight_sum", "mask", "all_saturated", "all_dark"):
        np.testing.assert_array_equal(getattr(tiled, name), getattr(whole, name), err_msg=name)


@pytest.mark.parametrize("cached", [False, True])
def test_repeat_merges_in_tiles_equal_one_tile(rng, cached):
    # N > 1: from the frames, or from the stack's cached repeat sums and extremes
    stack = _stack(rng, (8, 5), 3)
    if cached:
        stack.repeat_sum()
        stack.saturated()
    from photoquant.merge.debevec1997 import DebevecMergeOptions, merge_stack_Debevec1997

    opts = DebevecMergeOptions(weighting="hat")
    response = _model((8, 5), rng).response
    whole = merge_stack_Debevec1997(stack, response, opts, tile_rows=10**6, workers=1)
    tiled = merge_stack_Debevec1997(stack, response, opts, tile_rows=3, workers=2)
    assert (stack.cached_repeat_statistics() is not None) == cached  # the path under test
    for name in ("log_photoquantity", "weight_sum", "mask", "all_saturated", "all_dark"):
        np.testing.assert_array_equal(getattr(tiled, name), getattr(whole, name), err_msg=name)


def test_the_kept_merge_tables_never_stand_for_another_bracket(rng):
    """A camera keeps the tables of the last bracket it merged: a run of scenes each
    differing from the one before in one thing (the times, the repeats, the merge's
    options, the black level) corrects to the same bits as with a camera that kept
    nothing, and a scene of the same bracket reuses the tables."""
    shape = (9, 11)
    kept = _model(shape, rng)
    base = _stack(rng, shape, 1)
    every_value = {"exclude_below_valid_min": False}  # so that the black level's codes count
    dark = ExposureStack(
        base.frames, EXPOSURES, saturation_level=base.saturation_level, black_level=1.0
    )
    later = ExposureStack(base.frames, EXPOSURES * 1.25, saturation_level=base.saturation_level)
    # each scene differs from the one before it in one thing (or none: the second)
    scenes = [
        (base, None),
        (_stack(rng, shape, 1), None),  # the same bracket, other values
        (later, None),  # the times
        (base, None),
        (_stack(rng, shape, 3), None),  # the repeats
        (base, None),
        (base, every_value),  # the merge's options
        (dark, every_value),  # the black level
        (base, {"weighting": "hat"}),
    ]
    response = kept.balanced_response()
    seen = []
    for stack, options in scenes:
        merge = None if options is None else ("Debevec 1997", options)
        got = correct(stack, kept, refine_exposures=False, merge=merge)
        fresh = dataclasses.replace(kept)  # the same camera, nothing kept yet
        want = correct(stack, fresh, refine_exposures=False, merge=merge)
        np.testing.assert_array_equal(got.photoquantity, want.photoquantity)
        np.testing.assert_array_equal(got.mask, want.mask)
        seen.append(response._cache["merge_tables"][0][1])  # the last made or used
    # the same bracket: made once, and kept beside the last other one (other times,
    # other repeats) for the scene after it
    assert seen[1] is seen[0] and seen[3] is seen[0] and seen[5] is seen[0]
    assert len({id(t) for t in seen}) == len(seen) - 3  # every other change: made again
    assert len(response._cache["merge_tables"]) == 2


def test_tables_above_the_bound_are_not_kept(rng, monkeypatch):
    """Tables larger than the bound (the sums of many 16-bit repeats: hundreds of MB) are
    made for the scene and dropped; the correction is the same."""
    import photoquant.merge.debevec1997 as debevec

    shape = (9, 11)
    model, stack = _model(shape, rng), _stack(rng, shape, 1)
    want = correct(stack, model, refine_exposures=False)
    assert model.balanced_response()._cache["merge_tables"]
    monkeypatch.setattr(debevec, "_KEPT_TABLE_BYTES", 0)
    small = dataclasses.replace(model)
    got = correct(stack, small, refine_exposures=False)
    assert not small.balanced_response()._cache.get("merge_tables")
    np.testing.assert_array_equal(got.photoquantity, want.photoquantity)


@pytest.mark.parametrize("n_repeats", [1, 3])
@pytest.mark.parametrize("jitter", [0.0, 0.05])
def test_merging_while_the_times_are_tested_changes_no_bit(rng, monkeypatch, jitter, n_repeats):
    """A camera that tests a scene's times begins the merge with the nominal ones on the
    other threads meanwhile, keeps it where the test keeps them and merges again with the
    refined ones where it does not: the sequential correction's result, bit for bit."""
    from photoquant.merge._tiled import TileMerge

    shape = (48, 40)
    model = dataclasses.replace(_model(shape, rng), parameters={"refine_exposures": True})
    actual = EXPOSURES * np.exp(jitter * rng.standard_normal(EXPOSURES.size))
    l = log_uniform_scene(rng, (*shape, 3), decades=4.0)
    l[:3], l[-3:] = 1e3 * l.max(), 1e-4 * l.min()  # saturated, dark in every exposure
    frames = capture(l, actual, balance=BALANCE, noise_dn=1.5, n_repeats=n_repeats, rng=rng)
    stack = ExposureStack(frames, EXPOSURES, saturation_level=np.round(np.array(BALANCE) * 255))
    switches = []
    switch = TileMerge.switch
    monkeypatch.setattr(TileMerge, "switch", lambda *a: (switches.append(1), switch(*a))[1])
    alone = correct(stack, model, workers=1)  # tested first, then merged
    assert not switches
    fresh = dataclasses.replace(model)  # no scene tested yet
    both = correct(stack, fresh, workers=2, tile_rows=3)  # merged while tested
    assert both.exposure_decision == alone.exposure_decision
    assert both.exposure_decision.refine == (jitter > 0)
    assert len(switches) == (jitter > 0)  # the tiles merged with the nominal times redone
    for field in ("photoquantity", "mask", "all_saturated", "all_dark"):
        np.testing.assert_array_equal(getattr(both, field), getattr(alone, field), err_msg=field)
    assert both.all_saturated[:3].any() and both.all_dark[-3:].any()  # flags kept or redone
    assert both.notes == alone.notes


def test_a_failing_test_of_the_times_leaves_no_merge_running(rng, monkeypatch):
    import threading

    import photoquant.correction as correction

    shape = (48, 40)
    model = dataclasses.replace(_model(shape, rng), parameters={"refine_exposures": True})
    stack = _stack(rng, shape, 1)
    stopped = []
    begun = correction._start_one_pass

    def start(*args, **kwargs):  # the merge begun, watched
        one_pass = begun(*args, **kwargs)
        stopped.append(one_pass.merge._run)
        return one_pass

    def fail(*args):
        raise KeyboardInterrupt

    monkeypatch.setattr(correction, "_start_one_pass", start)
    monkeypatch.setattr(correction, "_scene_exposures", fail)
    with pytest.raises(KeyboardInterrupt):
        correct(stack, model, workers=2, tile_rows=1)
    assert stopped and not any(t.is_alive() for t in stopped[0]._threads)
    assert threading.active_count() >= 1


def test_a_camera_whose_last_scene_was_refined_tests_the_next_before_merging(rng, monkeypatch):
    """Merging while testing pays where the test keeps the times; a camera whose last
    tested scene was refined tests the next one first (the same result either way)."""
    import photoquant.correction as correction

    shape = (48, 40)
    model = dataclasses.replace(_model(shape, rng), parameters={"refine_exposures": True})
    l = log_uniform_scene(rng, (*shape, 3), decades=4.0)
    saturation = np.round(np.array(BALANCE) * 255)
    scenes = {}
    for name, jitter in (("right", 0.0), ("off", 0.05)):
        actual = EXPOSURES * np.exp(jitter * rng.standard_normal(EXPOSURES.size))
        frames = capture(l, actual, balance=BALANCE, noise_dn=1.5, n_repeats=1, rng=rng)
        scenes[name] = ExposureStack(frames, EXPOSURES, saturation_level=saturation)
    events = []
    start, test = correction._start_one_pass, correction._scene_exposures

    def merge_begun(*args, **kwargs):
        events.append("merge")
        return start(*args, **kwargs)

    def tested(*args):
        events.append("test")
        return test(*args)

    monkeypatch.setattr(correction, "_start_one_pass", merge_begun)
    monkeypatch.setattr(correction, "_scene_exposures", tested)
    order = []
    for name in ("right", "off", "off", "right", "right"):
        events.clear()
        got = correct(scenes[name], model, workers=2)
        assert got.exposure_decision.refine == (name == "off")
        order.append(events[0])
        want = correct(scenes[name], dataclasses.replace(model), workers=1)
        np.testing.assert_array_equal(got.photoquantity, want.photoquantity)
    # merged while tested: the first scene, and each after a scene whose times were kept
    assert order == ["merge", "merge", "test", "test", "merge"]
