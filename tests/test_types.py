"""String modes are Literal types (so mypy checks callers), and each tuple of accepted names is
derived from its Literal so the runtime check and the static type cannot drift apart."""

from __future__ import annotations

import typing

import numpy as np
import pytest

from coloradar import dsp
from coloradar.odometry import ORIENTATION_SOURCES, relative_pose_error
from coloradar.odometry.metrics import ALIGNMENTS, RPE_PAIRINGS
from coloradar.sim.raycast import cast_rays
from coloradar.sim.scenes import builtin_scene


def _literal_names(func, param):
    hint = typing.get_type_hints(func)[param]
    return set(typing.get_args(hint))


@pytest.mark.parametrize(("func", "param", "names"), [
    (dsp.cfar, "kind", dsp.CFAR_KINDS),
    (dsp.cfar_scale, "kind", dsp.CFAR_KINDS),
    (dsp.window, "name", dsp.WINDOWS),
    (dsp.range_fft, "window", dsp.WINDOWS),
    (dsp.combine_channels, "mode", dsp.OVERLAP_MODES),
    (relative_pose_error, "pairing", RPE_PAIRINGS),
])
def test_mode_parameters_are_literals_of_the_accepted_names(func, param, names):
    assert _literal_names(func, param) == set(names)


def test_processing_settings_fields_are_literals_of_the_accepted_names():
    hints = typing.get_type_hints(dsp.ProcessingSettings)
    for field, names in [("range_window", dsp.WINDOWS), ("doppler_window", dsp.WINDOWS),
                         ("cfar_kind", dsp.CFAR_KINDS), ("overlap", dsp.OVERLAP_MODES),
                         ("coupling_domain", dsp.COUPLING_DOMAINS),
                         ("angle_method", dsp.ANGLE_METHODS)]:
        assert set(typing.get_args(hints[field])) == set(names), field
        with pytest.raises(ValueError, match=field):
            dsp.ProcessingSettings(**{field: "nonsense"})
    assert set(ALIGNMENTS) == {"se3", "sim3", "posyaw", "origin", "none"}
    assert set(ORIENTATION_SOURCES) == {"imu", "groundtruth"}


def test_cast_rays_refuses_an_unknown_method_and_misses_parallel_planes():
    # Before, any unknown name silently meant "dense", and a ray exactly parallel to a plane
    # raised a RuntimeWarning (inf·0) under the suite's warnings-as-errors.
    rects = builtin_scene("corridor").static_rect_arrays
    rng = np.random.default_rng(0)
    d = rng.normal(size=(1, 600, 3))
    d[0, :6] = np.vstack([np.eye(3), -np.eye(3)])      # rays parallel to walls, floor, ceiling
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    origins = np.array([[[0.0, 0.0, 1.0]]])
    with pytest.raises(ValueError, match="method"):
        cast_rays(origins, d, rects, method="sector")  # type: ignore[arg-type]
    dense = cast_rays(origins, d, rects, method="dense")
    sectors = cast_rays(origins, d, rects, method="sectors")
    np.testing.assert_array_equal(dense[1], sectors[1])
    np.testing.assert_allclose(dense[0], sectors[0], rtol=1e-12)
    assert np.all(dense[1] >= 0)                       # a closed room: every ray hits
