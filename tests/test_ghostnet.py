"""GhostNet in Keras: timm ghostnet_100 naming, layouts, parameter count, and (where torch and timm
are installed) numerical agreement with timm itself."""
from __future__ import annotations

import importlib.abc
import importlib.machinery
import sys
import types

import numpy as np
import pytest

keras = pytest.importorskip("keras")
from safetensors.numpy import save_file  # noqa: E402

from greenloop.backbones import ghostnet as G  # noqa: E402


def _randomise_bn(model, seed=0):
    """Give every BatchNorm non-trivial statistics so the tests exercise them."""
    rng = np.random.default_rng(seed)
    for layer in model.layers:
        if isinstance(layer, keras.layers.BatchNormalization):
            c = layer.gamma.shape[0]
            layer.gamma.assign(rng.uniform(0.5, 1.5, c).astype(np.float32))
            layer.beta.assign(rng.normal(0, 0.1, c).astype(np.float32))
            layer.moving_mean.assign(rng.normal(0, 0.1, c).astype(np.float32))
            layer.moving_variance.assign(rng.uniform(0.5, 1.5, c).astype(np.float32))


@pytest.fixture(scope="module")
def full_model():
    keras.utils.set_random_seed(1)
    m = G.build_ghostnet(input_shape=(64, 64, 3), include_top=True, num_classes=1000)
    _randomise_bn(m, 1)
    return m


def test_layer_names_map_to_timm_paths():
    assert G.keras_layer_name("blocks.3.0.se.conv_reduce") == "blocks__3__0__se__conv_reduce"
    assert G.timm_module_path("blocks__3__0__se__conv_reduce") == "blocks.3.0.se.conv_reduce"
    m = G.build_ghostnet(input_shape=(None, None, 3))
    assert all("." not in layer.name for layer in m.layers)  # Keras's torch backend forbids dots


def test_make_divisible_matches_timm_rule():
    # SE reduced channels of ghostnet_100's SE blocks: make_divisible(mid * 0.25, 4)
    assert [G.make_divisible(c * 0.25, 4) for c in (72, 120, 480, 672, 960)] == [20, 32, 120, 168, 240]
    assert G.make_divisible(16, 4) == 16 and G.make_divisible(3, 4) == 4


def test_full_model_has_timm_tensor_and_parameter_counts(full_model):
    n_params = sum(int(np.prod(w.shape)) for w in full_model.trainable_weights)
    assert n_params == G.N_TIMM_PARAMS == 5_182_508
    sd = G.export_timm_state_dict(full_model)
    assert len(sd) == G.N_TIMM_TENSORS == 512
    # a few keys and torch layouts, straight from timm's state_dict
    assert sd["conv_stem.weight"].shape == (16, 3, 3, 3)
    assert sd["blocks.1.0.conv_dw.weight"].shape == (48, 1, 3, 3)
    assert sd["blocks.1.0.shortcut.2.weight"].shape == (24, 16, 1, 1)
    assert sd["blocks.3.0.se.conv_reduce.weight"].shape == (20, 72, 1, 1)
    assert sd["blocks.3.0.se.conv_expand.bias"].shape == (72,)
    assert sd["blocks.9.0.conv.weight"].shape == (960, 160, 1, 1)
    assert sd["blocks.9.0.bn1.running_var"].shape == (960,)
    assert sd["conv_head.weight"].shape == (1280, 960, 1, 1)
    assert sd["classifier.weight"].shape == (1000, 1280)
    assert sd["bn1.num_batches_tracked"].dtype == np.int64


def test_descriptor_shapes():
    m = G.build_ghostnet(input_shape=(None, None, 3))
    assert m.output_shape == (None, G.NUM_FEATURES)
    fm = G.build_ghostnet(input_shape=(64, 96, 3), pooling=None)
    assert fm.output_shape == (None, 2, 3, 960)
    with pytest.raises(ValueError, match="pooling"):
        G.build_ghostnet(pooling="max")


def test_timm_state_dict_round_trip(tmp_path, full_model):
    """Keras -> timm-named safetensors -> fresh Keras model gives identical outputs."""
    path = tmp_path / "ghostnet_100.safetensors"
    save_file(G.export_timm_state_dict(full_model), str(path))
    keras.utils.set_random_seed(2)  # different random init, overwritten by the load
    fresh = G.build_ghostnet(input_shape=(64, 64, 3), include_top=True)
    G.load_timm_weights(fresh, path)
    x = G.preprocess_input(np.random.default_rng(0).integers(0, 256, (2, 64, 64, 3)))
    np.testing.assert_array_equal(np.asarray(fresh.predict_on_batch(x)),
                                  np.asarray(full_model.predict_on_batch(x)))
    # a model without its top loads the same full file (conv_head/classifier are skipped) and
    # agrees with the pooled blocks.9 features of the full model
    headless = G.build_ghostnet(input_shape=(64, 64, 3))
    G.load_timm_weights(headless, path)
    last_map = full_model.get_layer(G.keras_layer_name("blocks.9.0.act")).output
    pooled = keras.Model(full_model.inputs, last_map)
    np.testing.assert_allclose(np.asarray(headless.predict_on_batch(x)),
                               np.asarray(pooled.predict_on_batch(x)).mean(axis=(1, 2)),
                               rtol=1e-5, atol=1e-6)


def test_load_errors(tmp_path, full_model):
    m = G.build_ghostnet(input_shape=(64, 64, 3))
    with pytest.raises(FileNotFoundError, match="huggingface-cli download"):
        G.load_timm_weights(m, tmp_path / "nope.safetensors")
    bad = tmp_path / "garbage.safetensors"
    bad.write_bytes(b"not a safetensors file at all")
    with pytest.raises(ValueError, match="safetensors"):
        G.load_timm_weights(m, bad)
    sd = G.export_timm_state_dict(full_model)
    missing = dict(sd)
    del missing["blocks.3.0.se.conv_reduce.weight"]
    with pytest.raises(ValueError, match="missing"):
        G.load_timm_state_dict(m, missing)
    extra = dict(sd, **{"blocks.5.0.ghost1.short_conv.0.weight": np.zeros((4, 4, 1, 1), np.float32)})
    with pytest.raises(ValueError, match="unexpected"):
        G.load_timm_state_dict(m, extra)
    wrong = dict(sd, **{"conv_stem.weight": np.zeros((20, 3, 3, 3), np.float32)})
    with pytest.raises(ValueError, match="shape"):
        G.load_timm_state_dict(m, wrong)


def test_preprocess_input_is_imagenet_mean_std():
    x = np.full((1, 2, 2, 3), 255, np.uint8)
    y = G.preprocess_input(x)
    np.testing.assert_allclose(y[0, 0, 0], (1 - G.IMAGENET_MEAN) / G.IMAGENET_STD, rtol=1e-6)
    assert y.dtype == np.float32


# ---- agreement with timm itself -------------------------------------------------------------

class _TorchvisionStub(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """Stands in for torchvision where it cannot be installed (no CPU build on PyPI for every torch).

    timm imports torchvision at module level only for helpers ghostnet never uses (transforms,
    datasets, FrozenBatchNorm2d); every attribute of the stub is an inert placeholder class.
    """

    def find_spec(self, fullname, path, target=None):
        if fullname == "torchvision" or fullname.startswith("torchvision."):
            return importlib.machinery.ModuleSpec(fullname, self, is_package=True)
        return None

    def create_module(self, spec):
        module = types.ModuleType(spec.name)
        module.__path__ = []

        def __getattr__(name):
            if name.startswith("__"):
                raise AttributeError(name)
            return _Placeholder(name, (), {})

        module.__getattr__ = __getattr__
        return module

    def exec_module(self, module):
        pass


class _Placeholder(type):
    def __getattr__(cls, name):
        if name.startswith("__"):
            raise AttributeError(name)
        return _Placeholder(name, (), {})


def _import_timm():
    pytest.importorskip("torch", reason="torch is not installed: timm comparison skipped",
                        exc_type=ImportError)
    stub = None
    try:
        import torchvision  # noqa: F401  (pyflakes: only probing)
    except Exception:  # absent, or a CUDA-only build that fails to load on this machine
        for name in [n for n in sys.modules if n == "torchvision" or n.startswith("torchvision.")]:
            del sys.modules[name]
        stub = _TorchvisionStub()
        sys.meta_path.insert(0, stub)
    try:
        import timm
    except ImportError as e:
        pytest.skip(f"timm is not installed or not importable ({e}): timm comparison skipped")
    finally:
        if stub is not None:
            sys.meta_path.remove(stub)
    return timm


def test_matches_timm_ghostnet_100():
    timm = _import_timm()
    import torch

    torch.manual_seed(0)
    tm = timm.create_model("ghostnet_100", pretrained=False).eval()
    g = torch.Generator().manual_seed(0)
    with torch.no_grad():  # non-trivial BatchNorm statistics
        for mod in tm.modules():
            if isinstance(mod, torch.nn.BatchNorm2d):
                c = mod.num_features
                mod.weight.copy_(torch.rand(c, generator=g) + 0.5)
                mod.bias.copy_(torch.randn(c, generator=g) * 0.1)
                mod.running_mean.copy_(torch.randn(c, generator=g) * 0.1)
                mod.running_var.copy_(torch.rand(c, generator=g) + 0.5)
    sd = {k: v.detach().cpu().numpy() for k, v in tm.state_dict().items()}
    assert len(sd) == G.N_TIMM_TENSORS
    assert sum(p.numel() for p in tm.parameters()) == G.N_TIMM_PARAMS

    km = G.build_ghostnet(input_shape=(None, None, 3), include_top=True)
    G.load_timm_state_dict(km, sd)
    kf = G.build_ghostnet(input_shape=(None, None, 3))
    G.load_timm_state_dict(kf, sd)
    rng = np.random.default_rng(0)
    for h, w in ((224, 224), (97, 131)):  # even and odd sizes: torch's symmetric padding
        x = rng.standard_normal((2, h, w, 3)).astype(np.float32)
        xt = torch.from_numpy(x.transpose(0, 3, 1, 2).copy())
        with torch.no_grad():
            logits = tm(xt).numpy()
            feats = tm.forward_features(xt).mean(dim=(2, 3)).numpy()
        np.testing.assert_allclose(np.asarray(km.predict_on_batch(x)), logits, atol=1e-4, rtol=0)
        np.testing.assert_allclose(np.asarray(kf.predict_on_batch(x)), feats, atol=1e-4, rtol=0)
    # and the export is timm's state dict, key for key
    exported = G.export_timm_state_dict(km)
    assert set(exported) == set(sd)
    for k in sd:
        np.testing.assert_array_equal(exported[k], sd[k].astype(exported[k].dtype))
