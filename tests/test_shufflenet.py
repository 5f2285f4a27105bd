"""ShuffleNet v2 in Keras: shapes at the study's input sizes, torchvision's parameter counts, channel
shuffle order, determinism, and a save / load round trip without Lambda layers."""
from __future__ import annotations

import numpy as np
import pytest

keras = pytest.importorskip("keras")

from greenloop.backbones import shufflenet as S  # noqa: E402


def _trainable(model) -> int:
    return int(sum(np.prod(w.shape) for w in model.trainable_weights))


@pytest.fixture(scope="module")
def small_model():
    """Width 0.5 at 64x64: the cheapest model to run, save and reload."""
    keras.utils.set_random_seed(3)
    return S.build_shufflenet_v2(input_shape=(64, 64, 3), width=0.5)


@pytest.mark.parametrize("hw", [(128, 128), (96, 64)])  # 224x224: see the parameter-count test
def test_pooled_descriptor_shape(hw):
    m = S.build_shufflenet_v2(input_shape=(*hw, 3), include_top=False, pooling="avg")
    x = S.preprocess_input(np.random.default_rng(0).uniform(0, 255, (2, *hw, 3)))
    y = np.asarray(m(x))
    assert y.shape == (2, S.NUM_FEATURES) == (2, 1024)
    assert np.all(np.isfinite(y)) and np.all(y >= 0)  # pooled ReLU output
    h, w = hw
    assert m.get_layer("stage2__0__shuffle_merge").output.shape == (None, h // 8, w // 8, 116)
    assert m.get_layer("conv5__2").output.shape == (None, h // 32, w // 32, 1024)


@pytest.mark.parametrize("width, expected", [(1.0, 2_278_604), (0.5, 1_366_792)])
def test_trainable_params_match_torchvision(width, expected):
    m = S.build_shufflenet_v2(include_top=True, width=width)
    assert _trainable(m) == S.trainable_params(m) == expected == S.N_TORCHVISION_PARAMS[width]
    assert m.output_shape == (None, 1000)
    assert m.get_layer("conv5__2").output.shape == (None, 7, 7, 1024)  # default 224x224 input
    # count_params adds BatchNorm's 2 moving statistics per channel (non-trainable)
    n_bn = sum(l.gamma.shape[0] for l in m.layers if isinstance(l, keras.layers.BatchNormalization))
    assert m.count_params() == expected + 2 * n_bn


def test_width_2_feature_map_has_2048_channels():
    m = S.build_shufflenet_v2(input_shape=(32, 32, 3), width=2.0, pooling=None)
    assert m.output_shape == (None, 1, 1, 2048)  # smallest input: 32x32 -> 1x1 after stage4


def test_channel_shuffle_order():
    x = np.arange(6, dtype=np.float32).reshape(1, 1, 1, 6)
    for shape in [(1, 1, 6), (None, None, 6)]:  # Reshape/Permute layers, then ChannelShuffle layer
        inp = keras.Input(shape)
        m = keras.Model(inp, S.channel_shuffle(inp, 2))
        y = np.asarray(m(x))
        np.testing.assert_array_equal(y.reshape(-1), [0, 3, 1, 4, 2, 5])
    # on a spatial map every pixel is shuffled the same way
    x = np.random.default_rng(0).normal(size=(2, 3, 5, 8)).astype(np.float32)
    inp = keras.Input((3, 5, 8))
    y = np.asarray(keras.Model(inp, S.channel_shuffle(inp, 2))(x))
    np.testing.assert_array_equal(y, x[..., [0, 4, 1, 5, 2, 6, 3, 7]])


def test_preprocess_input():
    x = np.full((1, 2, 2, 3), 255.0)
    y = S.preprocess_input(x)
    assert y.shape == x.shape and y.dtype == np.float32
    np.testing.assert_allclose(y[0, 0, 0], (1 - S.IMAGENET_MEAN) / S.IMAGENET_STD, rtol=1e-6)


def test_deterministic_with_seed(small_model):
    keras.utils.set_random_seed(3)  # the seed small_model was built with
    again = S.build_shufflenet_v2(input_shape=(64, 64, 3), width=0.5)
    assert len(again.weights) == len(small_model.weights)
    for a, b in zip(again.weights, small_model.weights):  # equal weights -> equal outputs
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    # the kernels really are random draws (so equality above is not vacuous)
    k = np.asarray(small_model.get_layer("conv1__0").kernel)
    assert np.unique(k).size == k.size


def test_save_load_round_trip(small_model, tmp_path):
    assert not any(isinstance(l, keras.layers.Lambda) for l in small_model.layers)
    path = tmp_path / "shufflenet.keras"
    small_model.save(path)
    loaded = keras.models.load_model(path)
    x = S.preprocess_input(np.random.default_rng(2).uniform(0, 255, (2, 64, 64, 3)))
    np.testing.assert_allclose(np.asarray(loaded(x)), np.asarray(small_model(x)), atol=1e-6)
    assert [l.name for l in loaded.layers] == [l.name for l in small_model.layers]


def test_channel_shuffle_layer_round_trip(tmp_path):
    """Unknown spatial size uses the registered ChannelShuffle layer; it must reload by itself."""
    inp = keras.Input((None, None, 6))
    m = keras.Model(inp, S.channel_shuffle(inp, 2, name="shuffle"))
    assert type(m.get_layer("shuffle")).__name__ == "ChannelShuffle"
    m.save(tmp_path / "shuffle.keras")
    loaded = keras.models.load_model(tmp_path / "shuffle.keras")
    x = np.broadcast_to(np.arange(6, dtype=np.float32), (2, 3, 5, 6))
    np.testing.assert_array_equal(np.asarray(loaded(x)), x[..., [0, 3, 1, 4, 2, 5]])


def test_rejects_bad_arguments():
    with pytest.raises(ValueError, match="width"):
        S.build_shufflenet_v2(width=0.75)
    with pytest.raises(ValueError, match="32x32"):
        S.build_shufflenet_v2(input_shape=(16, 64, 3))
    with pytest.raises(ValueError, match="pooling"):
        S.build_shufflenet_v2(pooling="max")
