"""Packed weights (visualenv.train.packed): the same numbers back, bit for bit, in less space than deflate alone."""

import io
import pickle
import zlib

import numpy as np
import pytest
from gymnasium import spaces

from visualenv.train import packed


@pytest.mark.parametrize("dtype", [np.float16, np.float32, np.float64, np.uint8, np.int64])
def test_arrays_come_back_bit_for_bit(dtype):
    values = np.random.default_rng(0).normal(0, 0.05, (64, 33, 3)).astype(dtype)
    values.reshape(-1)[:3] = [np.nan, np.inf, -0.0] if values.dtype.kind == "f" else [0, 1, 2]
    back = pickle.loads(pickle.dumps(packed.Packed(values)))
    assert back.dtype == values.dtype and back.shape == values.shape
    assert back.tobytes() == values.tobytes()  # NaN, inf and the sign of zero too
    assert back.flags.writeable


def test_float16_weights_take_less_space_than_deflate_alone():
    weights = np.random.default_rng(1).normal(0, 0.02, 200_000).astype(np.float16)  # like a layer's weights
    assert len(packed.planes(weights)) < 0.95 * len(zlib.compress(weights.tobytes(), 9))


def test_tensors_sharing_storage_are_stored_once_and_share_again():
    torch = pytest.importorskip("torch")
    weight = torch.randn(256, 64, dtype=torch.float16)
    state = {"a.weight": weight, "b.weight": weight.detach(), "small": torch.ones(3)}
    buffer = io.BytesIO()
    torch.save(packed.packed_state(state), buffer, pickle_protocol=4)
    once = buffer.tell()
    assert once < weight.nbytes  # one packed copy, not two
    loaded = torch.load(io.BytesIO(buffer.getvalue()), weights_only=False)
    assert torch.equal(loaded["a.weight"], weight) and loaded["a.weight"].dtype == torch.float16
    assert loaded["a.weight"] is loaded["b.weight"]
    assert torch.equal(loaded["small"], state["small"])


def test_dump_packs_arrays_wherever_they_are():
    """RLlib's checkpoint pickles: a dict of arrays, and a space whose bounds are arrays."""
    content = {"space": spaces.Box(0.0, 1.0, (100, 100, 4), np.float32), "weights": {"w": np.arange(5000, dtype=np.float32)}}
    plain, small = pickle.dumps(content, protocol=pickle.HIGHEST_PROTOCOL), io.BytesIO()
    packed.dump(content, small)
    assert len(small.getvalue()) < len(plain) / 10
    back = pickle.loads(small.getvalue())
    assert back["space"] == content["space"] and np.array_equal(back["weights"]["w"], content["weights"]["w"])
