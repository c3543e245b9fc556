"""The in-memory readback's conversions: Cycles' linear RGBA pass to the bytes Blender's 8-bit output holds."""

import numpy as np
import pytest

from visualenv.errors import RenderError
from visualenv.render.pixels import to_grayscale

pytest.importorskip("bpy")  # the capture lives in the Blender backend, which imports bpy
from visualenv.render.blender.capture import Capture  # noqa: E402

pytestmark = pytest.mark.blender


def srgb_bytes(linear: np.ndarray) -> np.ndarray:
    """The sRGB transfer function and round-half-up 8-bit quantisation, written out plainly."""
    x = np.clip(linear.astype(np.float64), 0.0, 1.0)
    encoded = np.where(x <= 0.0031308, x * 12.92, 1.055 * np.power(x, 1.0 / 2.4) - 0.055)
    return np.floor(encoded * 255.0 + 0.5).astype(np.uint8)


@pytest.fixture
def capture() -> Capture:
    """A 7x5 capture holding a pass as Cycles leaves it: RGBA rows, bottom row first, values out of range too."""
    rng = np.random.default_rng(0)
    c = Capture().arm(7, 5)
    values = rng.uniform(-0.2, 1.4, size=(5, 7, 4)).astype(np.float32)
    values[0, 0, :3] = (0.0, 1.0, 1e9)  # black, white and far past white in the bottom-left pixel
    c._buffer[:] = values.ravel()
    c._filled = True
    return c


def test_rows_come_out_top_first(capture):
    bottom_up = capture._buffer.reshape(5, 7, 4)
    expected = srgb_bytes(bottom_up[::-1, :, :3])
    rgb = capture.rgb()
    assert rgb.shape == (5, 7, 3) and rgb.dtype == np.uint8 and rgb.flags.c_contiguous
    assert np.abs(rgb.astype(int) - expected).max() <= 1  # the 16-bit table may round an exact tie the other way
    assert tuple(rgb[-1, 0]) == (0, 255, 255)  # the bottom-left pixel, clamped


def test_grayscale_is_the_luma_of_the_rgb_bytes(capture):
    gray = capture.grayscale()
    assert gray.shape == (5, 7, 1) and gray.flags.c_contiguous
    assert np.array_equal(gray, to_grayscale(capture.rgb()))


def test_grayscale_is_exact_over_byte_combinations():
    """The float32 luma shortcut equals (299 R + 587 G + 114 B + 500) // 1000 on 4,096 random colours."""
    levels = np.arange(256, dtype=np.float64)
    # linear values that land exactly on each sRGB byte: the inverse transfer function at each level's centre
    centre = levels / 255.0
    linear = np.where(centre <= 0.04045, centre / 12.92, ((centre + 0.055) / 1.055) ** 2.4).astype(np.float32)
    rng = np.random.default_rng(1)
    picks = rng.integers(0, 256, size=(64, 64, 3))
    c = Capture().arm(64, 64)
    rgba = np.ones((64, 64, 4), dtype=np.float32)
    rgba[:, :, :3] = linear[picks]
    c._buffer[:] = rgba.ravel()
    c._filled = True
    rgb = c.rgb()[::-1]
    assert np.array_equal(rgb, picks)  # each value lands on its byte
    expected = (299 * picks[..., 0] + 587 * picks[..., 1] + 114 * picks[..., 2] + 500) // 1000
    assert np.array_equal(c.grayscale()[::-1, :, 0], expected)


def test_raw_bytes_are_the_red_channel_unconverted(capture):
    raw = capture.raw()
    expected = np.floor(np.clip(capture._buffer.reshape(5, 7, 4)[::-1, :, 0] * 255.0 + 0.5, 0, 255)).astype(np.uint8)
    assert raw.shape == (5, 7, 1) and np.array_equal(raw[:, :, 0], expected)


def test_reading_before_a_render_filled_it_is_an_error():
    with pytest.raises(RenderError, match="Combined pass"):
        Capture().arm(4, 4).grayscale()


def test_luma_tables_are_exact_for_all_256_cubed_colours():
    """The float32 shortcut behind grayscale(): every (R, G, B) byte triple, against integer arithmetic."""
    from visualenv.render.blender.capture import LUMA_TABLES, SRGB_TABLE

    # one table entry per byte value (the first 16-bit level that encodes to it)
    first_level = np.searchsorted(SRGB_TABLE, np.arange(256))
    red, green, blue = (table[first_level] for table in LUMA_TABLES)
    shortcut = ((red[:, None, None] + green[None, :, None]) + blue[None, None, :]) * np.float32(0.001)
    r, g, b = np.ogrid[:256, :256, :256]
    assert np.array_equal(shortcut.astype(np.uint8), ((299 * r + 587 * g + 114 * b + 500) // 1000).astype(np.uint8))


def test_a_large_image_converted_in_bands_on_threads_gives_the_same_bytes():
    """Past 256² pixels per thread the rows are converted in bands on several threads: the result must not change,
    in particular at the bands' edges (rows flip bottom-first to top-first)."""
    rng = np.random.default_rng(2)
    values = rng.uniform(-0.2, 1.4, size=(601, 523 * 4)).astype(np.float32).ravel()  # uneven bands
    images = []
    for threads in (1, 3):
        c = Capture(threads=threads).arm(523, 601)
        c._buffer[:] = values
        c._filled = True
        images.append((c.grayscale(), c.rgb(), c.raw()))
        assert (c._pool is None) == (threads == 1)  # the bands did run on threads
        c.close()
    one, three = images
    assert all(np.array_equal(a, b) for a, b in zip(one, three))
    expected = srgb_bytes(values.reshape(601, 523, 4)[::-1, :, :3])
    assert np.abs(three[1].astype(int) - expected).max() <= 1 and np.array_equal(three[0], to_grayscale(three[1]))


def test_raw_rgb_and_grayscale_are_the_linear_values_as_bytes(capture):
    """physics.look 'mujoco' writes colours as they are (Blender's 'Raw' view): each channel rounded half up to a byte,
    the luma of those bytes."""
    expected = np.floor(np.clip(capture._buffer.reshape(5, 7, 4)[::-1, :, :3] * 255.0 + 0.5, 0, 255)).astype(np.uint8)
    assert np.array_equal(capture.rgb(raw=True), expected)
    assert np.array_equal(capture.grayscale(raw=True), to_grayscale(expected))
    assert not np.array_equal(capture.rgb(raw=True), capture.rgb())


def test_not_a_number_and_infinities_are_black_or_white_on_any_cpu():
    """A NaN in the pass is black, as a negative value is, without a warning: cast as it came, its level would be the
    CPU's (0 with SSE's conversion, 65535 with AVX-512's unsigned one). Infinities clamp."""
    c = Capture().arm(4, 1)
    c._buffer[:] = np.array(
        [np.nan, np.nan, np.nan, 1, -np.inf, 0.5, np.inf, 1, 1, 1, 1, 1, np.nan, 0, 1, 1], dtype=np.float32
    )
    c._filled = True
    with np.errstate(all="raise"):  # no 'invalid value encountered in cast'
        rgb, gray, raw = c.rgb(), c.grayscale(), c.raw()
    assert rgb[0].tolist() == [[0, 0, 0], [0, 188, 255], [255, 255, 255], [0, 0, 255]]
    assert np.array_equal(gray, to_grayscale(rgb)) and raw[0, :, 0].tolist() == [0, 0, 255, 0]
