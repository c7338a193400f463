"""Tests of nidar_mi.io.images: sRGB transfer functions, PNG, EXR and colour-map output."""

import os

import numpy as np
import OpenEXR
import pytest

from nidar_mi.errors import NidarError
from nidar_mi.io.images import (
    REC709_LUMA,
    linear_to_srgb,
    read_exr,
    read_png,
    srgb_to_linear,
    write_colormap_png,
    write_exr,
    write_png,
    write_srgb_png,
)

# --- sRGB ----------------------------------------------------------------------------------


def test_linear_to_srgb_reference_values():
    x = np.array([0.0, 0.0031308, 0.5, 1.0])
    # 12.92 * 0.0031308 = 0.040449936; 1.055 * 0.5**(1/2.4) - 0.055 = 0.735356983
    np.testing.assert_allclose(
        linear_to_srgb(x), [0.0, 0.040449936, 0.735356983, 1.0], rtol=0, atol=1e-9
    )
    np.testing.assert_allclose(linear_to_srgb(np.array([-0.5, 2.0])), [0.0, 1.0], atol=1e-12)


def test_srgb_branches_meet_at_the_boundary():
    below = linear_to_srgb(np.array([0.0031308]))
    above = linear_to_srgb(np.array([np.nextafter(0.0031308, 1.0)]))
    np.testing.assert_allclose(below, 0.04045, atol=1e-6)
    np.testing.assert_allclose(above, 0.04045, atol=1e-6)


def test_srgb_to_linear_reference_values():
    # the break is the encoded value of 0.0031308 (0.040449936), so the two curves invert
    y = np.array([0.0, 0.04, 0.040449936, 0.735356983, 1.0, 1.5])
    np.testing.assert_allclose(
        srgb_to_linear(y), [0.0, 0.04 / 12.92, 0.0031308, 0.5, 1.0, 1.0], rtol=0, atol=1e-9
    )


def test_srgb_curves_take_scalars_and_lists():
    assert np.ndim(linear_to_srgb(0.5)) == 0
    np.testing.assert_allclose(linear_to_srgb(0.5), 1.055 * 0.5 ** (1 / 2.4) - 0.055)
    np.testing.assert_allclose(linear_to_srgb([0.0, 1.0, 2.0]), [0.0, 1.0, 1.0])
    np.testing.assert_allclose(srgb_to_linear([0.0, 1.0, -1.0]), [0.0, 1.0, 0.0])
    assert np.isnan(linear_to_srgb(np.array([np.nan]))).all()


def test_rec709_luma_is_the_y_row_of_the_srgb_matrix():
    import colour

    y_row = colour.RGB_COLOURSPACES["sRGB"].matrix_RGB_to_XYZ[1]
    np.testing.assert_allclose(REC709_LUMA, y_row, atol=1e-4)
    assert sum(REC709_LUMA) == pytest.approx(1.0, abs=1e-12)


def test_srgb_round_trip_and_dtype():
    x = np.linspace(0.0, 1.0, 1001)
    np.testing.assert_allclose(srgb_to_linear(linear_to_srgb(x)), x, rtol=0, atol=1e-12)
    x32 = x.astype(np.float32)
    y32 = linear_to_srgb(x32)
    assert y32.dtype == np.float32
    np.testing.assert_allclose(srgb_to_linear(y32), x32, rtol=1e-4, atol=1e-6)


# --- PNG -----------------------------------------------------------------------------------


@pytest.mark.parametrize("shape", [(5, 7), (5, 7, 3), (5, 7, 4)])
def test_png_round_trip(tmp_path, shape):
    img = np.random.default_rng(0).integers(0, 256, shape).astype(np.uint8)
    write_png(tmp_path / "d" / "i.png", img)
    got = read_png(tmp_path / "d" / "i.png")
    assert got.dtype == np.uint8
    np.testing.assert_array_equal(got, img)
    assert os.listdir(tmp_path / "d") == ["i.png"]


@pytest.mark.parametrize(
    "img", [np.zeros((4, 4), np.float32), np.zeros((4, 4, 2), np.uint8), np.zeros(4, np.uint8)]
)
def test_png_refuses_bad_input(tmp_path, img):
    with pytest.raises(NidarError, match="write_png"):
        write_png(tmp_path / "i.png", img)
    assert os.listdir(tmp_path) == []


def test_png_unreadable(tmp_path):
    (tmp_path / "g.png").write_bytes(b"\x89PNG garbage")
    with pytest.raises(NidarError, match=r"cannot read .*g\.png"):
        read_png(tmp_path / "g.png")


# --- EXR -----------------------------------------------------------------------------------


def test_exr_round_trip_exact(tmp_path):
    rng = np.random.default_rng(1)
    ch = {"depth": rng.uniform(0, 100, (6, 9)).astype(np.float32), "R": rng.normal(size=(6, 9))}
    ch["depth"][0, 0] = np.nan
    write_exr(tmp_path / "a.exr", ch)
    got = read_exr(tmp_path / "a.exr")
    assert sorted(got) == ["R", "depth"]
    assert all(v.dtype == np.float32 and v.shape == (6, 9) for v in got.values())
    np.testing.assert_array_equal(got["depth"], ch["depth"])
    np.testing.assert_array_equal(got["R"], ch["R"].astype(np.float32))
    f = OpenEXR.File(str(tmp_path / "a.exr"), header_only=True)
    assert f.header()["compression"] == OpenEXR.ZIP_COMPRESSION


def test_exr_rgb_image_split(tmp_path):
    rgb = np.random.default_rng(2).uniform(size=(4, 5, 3)).astype(np.float32)
    write_exr(tmp_path / "rgb.exr", {"RGB": rgb})
    got = read_exr(tmp_path / "rgb.exr")
    assert sorted(got) == ["B", "G", "R"]
    np.testing.assert_array_equal(np.stack([got["R"], got["G"], got["B"]], -1), rgb)


@pytest.mark.parametrize(
    "channels",
    [{}, {"a": np.zeros((2, 2)), "b": np.zeros((3, 2))}, {"a": np.zeros((2, 2, 3))}],
)
def test_exr_refuses_bad_channels(tmp_path, channels):
    with pytest.raises(NidarError, match="write_exr"):
        write_exr(tmp_path / "a.exr", channels)
    assert os.listdir(tmp_path) == []


def test_exr_unreadable(tmp_path):
    (tmp_path / "g.exr").write_bytes(b"not an exr")
    with pytest.raises(NidarError, match=r"cannot read .*g\.exr: not an OpenEXR"):
        read_exr(tmp_path / "g.exr")


# --- colour map and sRGB PNG ---------------------------------------------------------------

# First and last entries of the published Turbo colour map (Mikhailov 2019), in 8 bits.
TURBO_LOW = [48, 18, 59]  # (0.18995, 0.07176, 0.23217) * 255
TURBO_HIGH = [122, 4, 3]  # (0.47960, 0.01583, 0.01055) * 255


def test_colormap_png_explicit_range_and_invalid(tmp_path):
    img = np.array([[0.0, 10.0, -5.0], [np.nan, 20.0, 5.0]])
    invalid = np.array([[False, False, False], [False, False, True]])
    write_colormap_png(tmp_path / "c.png", img, vmin=0.0, vmax=10.0, invalid=invalid)
    got = read_png(tmp_path / "c.png")
    assert got.shape == (2, 3, 3)
    np.testing.assert_array_equal(got[0, 0], TURBO_LOW)
    np.testing.assert_array_equal(got[0, 1], TURBO_HIGH)
    np.testing.assert_array_equal(got[0, 2], TURBO_LOW)  # below vmin: clipped
    np.testing.assert_array_equal(got[1, 1], TURBO_HIGH)  # above vmax: clipped
    np.testing.assert_array_equal(got[1, 0], [0, 0, 0])  # NaN
    np.testing.assert_array_equal(got[1, 2], [0, 0, 0])  # masked


def test_colormap_png_default_percentiles(tmp_path):
    # 0..100: the 1st/99th percentiles are 1 and 99, so 0..1 and 99..100 saturate.
    img = np.arange(101, dtype=np.float64).reshape(1, 101)
    write_colormap_png(tmp_path / "c.png", img, cmap="gray")
    got = read_png(tmp_path / "c.png")[0, :, 0].astype(int)
    assert got[0] == got[1] == 0 and got[99] == got[100] == 255
    # gray is the identity map: value 50 -> (50 - 1) / 98 = 0.5 -> 128 (from 127.5)
    assert abs(got[50] - 127.5) <= 0.5
    assert np.all(np.diff(got) >= 0)


def test_colormap_png_errors(tmp_path):
    write_colormap_png(tmp_path / "all_nan.png", np.full((2, 2), np.nan))
    np.testing.assert_array_equal(read_png(tmp_path / "all_nan.png"), 0)
    with pytest.raises(NidarError, match="colour map"):
        write_colormap_png(tmp_path / "c.png", np.zeros((2, 2)), cmap="no_such_map")
    with pytest.raises(NidarError, match="mask"):
        write_colormap_png(tmp_path / "c.png", np.zeros((2, 2)), invalid=np.zeros(3, bool))
    assert os.listdir(tmp_path) == ["all_nan.png"]


def test_srgb_png(tmp_path):
    rgb = np.array([[[0.0, 0.5, 1.0], [np.nan, 2.0, -1.0]]])
    write_srgb_png(tmp_path / "s.png", rgb)
    # 0.5 -> 0.735357 * 255 = 187.52 -> 188
    np.testing.assert_array_equal(read_png(tmp_path / "s.png"), [[[0, 188, 255], [0, 255, 0]]])
    with pytest.raises(NidarError, match="H,W,3"):
        write_srgb_png(tmp_path / "x.png", np.zeros((2, 2)))
