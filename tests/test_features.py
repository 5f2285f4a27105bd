"""greenloop.features: descriptor shapes, weights handling (offline-safe), input checks, and the
weight-free descriptors (pixels, SIFT bag of words) and the main paper's CNN (spot_cnn).

Small and fast: 8 frames, 32x32 CNN inputs, random-initialised networks (weights=None)."""
from __future__ import annotations

import warnings

import cv2
import numpy as np
import pytest

keras = pytest.importorskip("keras")
from safetensors.numpy import save_file  # noqa: E402

from greenloop import features as F  # noqa: E402
from greenloop.backbones import efficientnet_lite as LITE  # noqa: E402
from greenloop.backbones import ghostnet as G  # noqa: E402
from greenloop.features import cnn as FCNN  # noqa: E402
from greenloop.datasets import sequence  # noqa: E402

SIZE = 32  # smallest input every Keras application accepts
DIMS = {"vgg19": 512, "resnet50": 2048, "resnet101": 2048, "resnet152": 2048,
        "efficientnetb0": 1280, "mobilenetv3small": 576, "ghostnet": 960,
        "mobilenetv1": 1024, "mobilenetv2": 1280, "efficientnetlite0": 1280,
        "inceptionv3": 2048, "vgg19_fc1": 4096, "shufflenetv2": 1024}


@pytest.fixture(autouse=True)
def empty_keras_home(tmp_path, monkeypatch):
    """No ImageNet weights visible: tests never depend on (or download) real weight files (the
    GREENLOOP_WEIGHTS folders and the installed Lite0 weights package are hidden too)."""
    home = tmp_path / "keras_home"
    (home / "models").mkdir(parents=True)
    monkeypatch.setenv("KERAS_HOME", str(home))
    monkeypatch.delenv(F.WEIGHTS_ENV, raising=False)
    monkeypatch.setattr(LITE, "package_weights_path", lambda: None)
    return home


def shapes_frames(n=8, w=96, h=72, seed=0):
    """Synthetic RGB uint8 frames with random filled shapes on a noisy background."""
    rng = np.random.default_rng(seed)
    out = np.empty((n, h, w, 3), np.uint8)
    for i in range(n):
        im = rng.integers(0, 60, (h, w, 3), dtype=np.uint8)
        for _ in range(6):
            colour = tuple(int(c) for c in rng.integers(60, 256, 3))
            x, y = (int(v) for v in rng.integers(5, min(w, h) - 5, 2))
            r = int(rng.integers(4, 14))
            if rng.random() < 0.5:
                cv2.circle(im, (x, y), r, colour, -1)
            else:
                cv2.rectangle(im, (x - r, y - r), (x + r, y + r // 2), colour, -1)
        out[i] = im
    return out


@pytest.fixture(scope="module")
def frames():
    return shapes_frames()


def write_sequence(folder, rgb, depth_m=None):
    (folder / "rgb").mkdir(parents=True)
    for i, im in enumerate(rgb):
        cv2.imwrite(str(folder / "rgb" / f"{i}.png"), cv2.cvtColor(im, cv2.COLOR_RGB2BGR))
    if depth_m is not None:
        (folder / "depth").mkdir()
        for i, d in enumerate(depth_m):
            cv2.imwrite(str(folder / "depth" / f"{i}.png"),
                        np.rint(d * sequence.DEPTH_SCALE).astype(np.uint16))
    return folder


# ---- names, dims ------------------------------------------------------------------------------

def test_backbone_table():
    assert set(F.BACKBONES) == set(DIMS) | {"sift_bovw", "pixels", "spot_cnn", "pixels-patchnorm",
                                            "gradients", "gradients+efficientnetlite0", F.FUSED_INT8}
    for name, d in DIMS.items():
        assert F.BACKBONES[name].dim == d
        assert F.BACKBONES[name].input_size == (224, 224)
        assert F.BACKBONES[name].weights_file or name == "shufflenetv2"   # no weights exist offline
    assert F.BACKBONES["pixels"].dim == F.BACKBONES["pixels-patchnorm"].dim == 1024
    assert F.BACKBONES["gradients"].dim == (128 // 16) * (64 // 16) * 8 == 256
    assert F.BACKBONES["gradients+efficientnetlite0"].dim == 256 + 4 * 112    # block 10: 112 channels, 2 x 2 cells
    assert F.BACKBONES[F.FUSED_INT8].dim == F.FUSED_DIM and F.BACKBONES[F.FUSED_INT8].kind == "fused"   # its int8 graph


def test_unknown_backbone_lists_valid_names(frames):
    with pytest.raises(ValueError, match="vgg19.*ghostnet"):
        F.extract(frames, "alexnet")
    with pytest.raises(ValueError, match="unknown backbone"):
        F.weights_used("shufflenetv3", None)


@pytest.mark.parametrize("backbone", ["vgg19", "resnet50", "efficientnetb0", "mobilenetv3small",
                                      "ghostnet", "efficientnetlite0"])
def test_cnn_descriptor_shapes(frames, backbone):
    X, info = F.extract(frames, backbone, weights=None, input_size=SIZE, batch_size=len(frames),
                        progress=False, return_info=True)
    assert X.shape == (len(frames), DIMS[backbone]) and X.dtype == np.float32
    assert np.isfinite(X).all()
    assert info.weights == "random init" and info.label == f"{backbone} (random init)"
    assert info.dim == DIMS[backbone] and info.input_size == (SIZE, SIZE)
    assert info.seconds_per_image > 0


@pytest.mark.parametrize("backbone", ["resnet101", "resnet152"])
def test_deep_resnets_build(backbone):
    """Same code path as resnet50; building (not running) them keeps the suite fast."""
    model = FCNN._cnn_model(backbone, None, (SIZE, SIZE))
    assert model.output_shape == (None, DIMS[backbone])
    F.clear_cache()


def test_inception_and_vgg19_fc1_build():
    """InceptionV3 (Inception-v4's stand-in) needs >= 75x75; vgg19_fc1 is the whole classifier cut
    at fc1, so it runs at 224x224 only and says why."""
    assert FCNN._cnn_model("inceptionv3", None, (75, 75)).output_shape == (None, 2048)
    fc1 = FCNN._cnn_model("vgg19_fc1", None, (224, 224))
    assert fc1.output_shape == (None, 4096) and fc1.layers[-1].name == "fc1"
    F.clear_cache()
    with pytest.raises(ValueError, match="fixed 224x224.*fully connected"):
        F.extract(np.zeros((1, 32, 32, 3), np.uint8), "vgg19_fc1", None, input_size=SIZE)


def test_shufflenet_is_random_init_only(frames):
    X, info = F.extract(frames, "shufflenetv2", None, input_size=SIZE, progress=False, return_info=True)
    assert X.shape == (len(frames), 1024) and np.isfinite(X).all() and info.weights == "random init"
    assert F.weights_used("shufflenetv2") == "random init"
    with pytest.warns(UserWarning, match="RANDOM-INITIALISED.*no ImageNet weights file"):
        F.extract(frames[:1], "shufflenetv2", "auto", input_size=SIZE, progress=False)
    with pytest.raises(F.WeightsNotFoundError, match="shufflenetv2 has no ImageNet weights"):
        F.extract(frames, "shufflenetv2", "imagenet", input_size=SIZE, progress=False)
    F.clear_cache()


def test_partial_batches(frames):
    full = F.extract(frames, "mobilenetv3small", None, input_size=SIZE, batch_size=8,
                     progress=False)
    np.testing.assert_allclose(F.extract(frames, "mobilenetv3small", None, input_size=SIZE,
                                         batch_size=3, progress=False), full, rtol=1e-5, atol=1e-6)


def test_random_init_is_deterministic(frames):
    a = F.extract(frames, "ghostnet", None, input_size=SIZE, progress=False)
    F.clear_cache()  # rebuild from scratch
    b = F.extract(frames, "ghostnet", None, input_size=SIZE, progress=False)
    np.testing.assert_array_equal(a, b)
    assert not np.allclose(a[0], a[1])  # different frames, different descriptors


def test_input_forms_agree(frames):
    """uint8, float [0, 1], other sizes (resized) and single-channel frames are all accepted."""
    kw = dict(backbone="mobilenetv3small", weights=None, input_size=SIZE, progress=False)
    u8 = F.extract(frames, **kw)
    fl = F.extract(frames.astype(np.float32) / 255, **kw)
    np.testing.assert_allclose(fl, u8, rtol=1e-4, atol=1e-4)
    small = np.stack([cv2.resize(f, (SIZE, SIZE), interpolation=cv2.INTER_AREA) for f in frames])
    np.testing.assert_allclose(F.extract(small, **kw), u8, rtol=1e-5, atol=1e-5)
    gray = frames[..., 1]
    g2 = F.extract(gray, **kw)
    np.testing.assert_array_equal(F.extract(gray[..., None], **kw), g2)
    np.testing.assert_array_equal(F.extract(np.repeat(gray[..., None], 3, -1), **kw), g2)


def test_folder_input(tmp_path, frames):
    folder = write_sequence(tmp_path / "seq", frames)
    kw = dict(backbone="mobilenetv3small", weights=None, input_size=SIZE, progress=False)
    loaded = sequence.load_frames(folder, size=(SIZE, SIZE), gray=False, dtype=np.uint8)
    np.testing.assert_array_equal(F.extract(folder, **kw), F.extract(loaded, **kw))
    assert F.extract(folder, limit=3, **kw).shape == (3, 576)


# ---- weights ----------------------------------------------------------------------------------

def test_auto_falls_back_loudly_without_weights(frames):
    assert F.imagenet_weights_path("ghostnet") is None
    assert F.weights_used("ghostnet", "auto") == "random init"
    with pytest.warns(UserWarning, match="RANDOM-INITIALISED.*ghostnet_100.in1k.safetensors"):
        X, info = F.extract(frames, "ghostnet", "auto", input_size=SIZE, progress=False,
                            return_info=True)
    assert info.weights == "random init" and "random init" in info.label
    np.testing.assert_array_equal(X, F.extract(frames, "ghostnet", None, input_size=SIZE,
                                               progress=False))


def test_auto_uses_local_imagenet_file(frames, empty_keras_home):
    keras.utils.set_random_seed(7)
    donor = G.build_ghostnet(input_shape=(None, None, 3), include_top=True)
    path = empty_keras_home / "models" / G.WEIGHTS_FILENAME
    save_file(G.export_timm_state_dict(donor), str(path))
    assert F.imagenet_weights_path("ghostnet") == path
    assert F.weights_used("ghostnet", "auto") == "imagenet"
    with warnings.catch_warnings():
        warnings.simplefilter("error", UserWarning)  # no fallback warning
        X, info = F.extract(frames, "ghostnet", "auto", input_size=SIZE, progress=False,
                            return_info=True)
    assert info.weights == "imagenet"
    by_path, info_p = F.extract(frames, "ghostnet", str(path), input_size=SIZE, progress=False,
                                return_info=True)
    assert info_p.weights == f"file:{G.WEIGHTS_FILENAME}"
    np.testing.assert_allclose(X, by_path, rtol=1e-6, atol=1e-6)
    assert not np.allclose(X, F.extract(frames, "ghostnet", None, input_size=SIZE, progress=False))


def test_imagenet_ghostnet_offline_names_the_file(frames):
    with pytest.raises(F.WeightsNotFoundError, match="ghostnet_100.in1k.safetensors"):
        F.extract(frames, "ghostnet", "imagenet", input_size=SIZE, progress=False)
    assert issubclass(F.WeightsNotFoundError, FileNotFoundError)


def test_missing_weights_path(frames, tmp_path):
    with pytest.raises(FileNotFoundError, match="not found"):
        F.extract(frames, "vgg19", tmp_path / "nope.h5", input_size=SIZE, progress=False)
    with pytest.raises(ValueError, match="weights must be"):
        F.extract(frames, "vgg19", 3, input_size=SIZE, progress=False)


def test_wrong_architecture_weights(frames, tmp_path):
    inp = keras.Input((8, 8, 3))
    tiny = keras.Model(inp, keras.layers.Conv2D(4, 3)(inp))
    path = tmp_path / "tiny.weights.h5"
    tiny.save_weights(str(path))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # Keras lists every layer it could not load
        with pytest.raises(ValueError, match="does not fit mobilenetv3small"):
            F.extract(frames, "mobilenetv3small", path, input_size=SIZE, progress=False)
    wrong = tmp_path / "other.safetensors"
    save_file({"conv_stem.weight": np.zeros((8, 3, 3, 3), np.float32)}, str(wrong))
    with pytest.raises(ValueError, match="not timm's ghostnet_100"):
        F.extract(frames, "ghostnet", wrong, input_size=SIZE, progress=False)


# ---- bad frames -------------------------------------------------------------------------------

@pytest.mark.parametrize("bad, match", [
    (np.zeros((4, 32, 32, 2), np.uint8), "shape"),
    (np.zeros((32, 32, 3), np.uint8), "frames\\[None\\]"),
    (np.zeros((0, 32, 32, 3), np.uint8), "N >= 1"),
    (np.zeros((2, 32), np.uint8), "shape"),
    (np.full((2, 32, 32, 3), 2.0, np.float32), "\\[0, 1\\]"),
    (np.zeros((2, 32, 32), np.uint16), "dtype"),
])
def test_bad_frames(bad, match):
    with pytest.raises(ValueError, match=match):
        F.extract(bad, "pixels")


def test_bad_arguments(frames):
    with pytest.raises(ValueError, match="at least 32"):
        F.extract(frames, "vgg19", None, input_size=16, progress=False)
    for name in ("mobilenetv1", "mobilenetv2"):  # the TFLite graphs' size, with or without them
        assert F.BACKBONES[name].fixed_input
        with pytest.raises(ValueError, match="fixed 224x224.*input_size=None"):
            F.extract(frames, name, None, input_size=SIZE, progress=False)
    with pytest.raises(ValueError, match="batch_size"):
        F.extract(frames, "pixels", batch_size=0)
    with pytest.raises(ValueError, match="no weights"):
        F.extract(frames, "pixels", weights="imagenet")


# ---- weight-free descriptors ------------------------------------------------------------------

def test_pixels_is_the_main_papers_preprocessing(tmp_path, frames):
    X, info = F.extract(frames, "pixels", return_info=True)
    assert X.shape == (len(frames), 1024) and info.weights == "none"
    assert 0.0 <= X.min() and X.max() <= 1.0
    expected = np.stack([cv2.resize(cv2.cvtColor(f, cv2.COLOR_RGB2GRAY), (32, 32),
                                    interpolation=cv2.INTER_AREA) for f in frames])
    np.testing.assert_allclose(X, expected.reshape(len(frames), -1) / 255.0, atol=1e-6)
    folder = write_sequence(tmp_path / "seq", frames)
    Xf = F.extract(folder, "pixels", progress=False)
    np.testing.assert_array_equal(Xf, sequence.load_frames(folder).reshape(len(frames), -1))
    assert np.abs(Xf - X).max() <= 1 / 255 + 1e-6  # gray from file vs from RGB array: rounding only


def test_sift_bovw(frames):
    X, info = F.extract(frames, "sift_bovw", vocab_size=24, seed=0, progress=False,
                        return_info=True)
    V = info.extra["vocabulary"]
    assert X.shape == (len(frames), len(V)) and V.shape[1] == 128 and 1 <= len(V) <= 24
    assert info.dim == len(V) and info.weights == "none" and info.extra["vocabulary_fitted_on_input"]
    assert np.isfinite(X).all() and (X >= 0).all() and (X.sum(1) > 0).all()
    # deterministic, and a passed vocabulary reproduces the features
    np.testing.assert_array_equal(X, F.extract(frames, "sift_bovw", vocab_size=24, seed=0,
                                               progress=False))
    np.testing.assert_allclose(F.extract(frames, "sift_bovw", vocabulary=V, progress=False), X,
                               rtol=1e-6)
    # the same frame twice gives the same row; another frame a different one
    twice = np.concatenate([frames[:3], frames[:1]])
    Y = F.extract(twice, "sift_bovw", vocabulary=V, progress=False)
    np.testing.assert_array_equal(Y[0], Y[3])
    assert not np.allclose(Y[0], Y[1])
    V2 = F.fit_vocabulary(frames, size=24, seed=0)
    assert V2.shape == V.shape
    with pytest.raises(ValueError, match="vocabulary"):
        F.extract(frames, "sift_bovw", vocabulary=np.zeros((5, 64)), progress=False)
    with pytest.raises(ValueError, match="no SIFT keypoints"):
        F.extract(np.zeros((2, 40, 40, 3), np.uint8), "sift_bovw", progress=False)


# ---- the main paper's CNN ---------------------------------------------------------------------

def paper_cnn(n_classes=5):
    """The architecture of greenloop.methods.dictionary.cnn.build: Conv2D(32, 3x3, relu) -> Flatten -> Dense(68, relu)
    -> Dense(n, softmax) on (32, 32, 1); fewer filters here to stay fast."""
    keras.utils.set_random_seed(3)
    inp = keras.Input((32, 32, 1))
    x = keras.layers.Conv2D(4, 3, activation="relu")(inp)
    x = keras.layers.Flatten()(x)
    feat = keras.layers.Dense(68, activation="relu", name="dense_68")(x)
    out = keras.layers.Dense(n_classes, activation="softmax")(feat)
    return keras.Model(inp, out), feat


def test_spot_cnn_penultimate_layer(frames, tmp_path):
    model, _ = paper_cnn()
    X, info = F.extract(frames, "spot_cnn", weights=model, progress=False, return_info=True)
    assert X.shape == (len(frames), 68) and (X >= 0).all()
    assert info.weights == f"model:{model.name}"
    gray = F.extract(frames, "pixels").reshape(-1, 32, 32, 1)
    ref = keras.Model(model.input, model.get_layer("dense_68").output).predict_on_batch(gray)
    np.testing.assert_allclose(X, np.asarray(ref), rtol=1e-5, atol=1e-6)
    path = tmp_path / "cnn.keras"
    model.save(str(path))
    Xp, info_p = F.extract(frames, "spot_cnn", weights=path, progress=False, return_info=True)
    np.testing.assert_allclose(Xp, X, rtol=1e-5, atol=1e-6)
    assert info_p.weights == "file:cnn.keras"
    with pytest.raises(ValueError, match="trained model"):
        F.extract(frames, "spot_cnn")
    with pytest.raises(FileNotFoundError):
        F.extract(frames, "spot_cnn", weights=tmp_path / "missing.keras")


# ---- RGB-D, timing ----------------------------------------------------------------------------

def test_depth_to_uint8():
    d = np.array([[[0.0, 2.5, 10.0, 30.0, np.nan]]], np.float32)
    np.testing.assert_array_equal(F.depth_to_uint8(d), [[[0, 64, 255, 255, 0]]])
    with pytest.raises(ValueError):
        F.depth_to_uint8(d, max_depth=0)


def test_extract_rgbd(tmp_path, frames):
    rng = np.random.default_rng(1)
    depth = rng.uniform(0.3, 6.0, frames.shape[:3]).astype(np.float32)
    folder = write_sequence(tmp_path / "seq", frames, depth)
    X, info = F.extract_rgbd(folder, "mobilenetv3small", weights=None, input_size=SIZE,
                             progress=False, return_info=True)
    assert X.shape == (len(frames), 2 * 576) and info.dim == 2 * 576
    rgb = F.extract(folder, "mobilenetv3small", None, input_size=SIZE, progress=False)
    np.testing.assert_array_equal(X[:, :576], rgb)
    d8 = F.depth_to_uint8(sequence.load_depth(folder, size=(SIZE, SIZE)))
    np.testing.assert_array_equal(X[:, 576:], F.extract(d8, "mobilenetv3small", None,
                                                        input_size=SIZE, progress=False))
    with pytest.raises(FileNotFoundError, match="depth"):
        F.extract_rgbd(write_sequence(tmp_path / "rgb_only", frames), "pixels")


def test_time_per_image():
    t = F.time_per_image("mobilenetv3small", weights=None, input_size=SIZE, n_images=6,
                         batch_size=4)
    assert 0 < t < 5
    assert F.time_per_image("pixels", n_images=4) > 0


def test_backbone_entries_name_their_weights():
    assert F.split_spec("vgg19", "auto") == ("vgg19", "auto")
    assert F.split_spec("mobilenetv2:random", "auto") == ("mobilenetv2", None)
    assert F.split_spec("resnet50:imagenet", None) == ("resnet50", "imagenet")
    with pytest.raises(ValueError, match="suffix"):
        F.split_spec("vgg19:pretrained")
    with pytest.raises(ValueError):
        F.split_spec("alexnet")


def test_a_study_wide_cnn_input_keeps_fixed_inputs_and_the_suffix_forces_random_init():
    frames = np.random.default_rng(0).integers(0, 255, (2, 40, 48, 3), dtype=np.uint8)
    X, info = F.get("mobilenetv2:random", "auto", cnn_input_size=64).extract(frames)
    assert X.shape == (2, 1280) and info.weights == "random init" and info.input_size == (224, 224)
    X, info = F.get("pixels", "auto", cnn_input_size=64).extract(frames)
    assert X.shape == (2, 1024)


def test_extract_all_computes_each_descriptor_once(tiny_sequence, tmp_path, capsys):
    specs = ["pixels", "ghostnet:random"]
    a, ia = F.extract_all(tiny_sequence, specs, input_size=32, step=5, cache=tmp_path)
    assert len(list(tmp_path.glob("*/features.npy"))) == 2
    b, ib = F.extract_all(tiny_sequence, specs, input_size=32, step=5, cache=tmp_path)
    for s in specs:
        assert np.array_equal(a[s], b[s]) and ia[s] == ib[s] and a[s].shape[0] == 40
    assert np.array_equal(a["pixels"], F.extract(tiny_sequence, "pixels", step=5, progress=False))
    F.extract_all(tiny_sequence, specs, input_size=32, step=4, cache=tmp_path)   # other settings: new entries
    assert len(list(tmp_path.glob("*/features.npy"))) == 4
    assert "ghostnet (random init)" in capsys.readouterr().out


def test_random_init_fallback_is_reported_in_one_line_without_paths(frames, capsys):
    """A notebook's extraction with weights="auto" and no weight file: one printed line naming
    the backbone, and no UserWarning (whose text would carry a path into the package)."""
    import warnings
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        with F.random_init_reported(F.get("ghostnet", "auto", warn=False)):
            X = F.extract(frames, "ghostnet", "auto", input_size=64)
    out = capsys.readouterr().out
    assert out.count("RANDOM-INITIALISED") == 1 and out.startswith("ghostnet:") and "/" not in out.split("(")[0]
    assert not [w for w in caught if "RANDOM-INITIALISED" in str(w.message)]
    assert X.shape == (len(frames), 960)
    with warnings.catch_warnings(record=True) as caught:   # without the context the warning is raised
        warnings.simplefilter("always")
        F.extract(frames, "ghostnet", "auto", input_size=64)
    assert [w for w in caught if "RANDOM-INITIALISED" in str(w.message)]


# ---- one registry, one protocol, weights resolved once ------------------------------------------

def test_sequence_descriptors_are_registry_entries():
    """greenloop-seq's names are the features registry's: every one a BACKBONES entry with an
    extractor, and seqmatch's tuple is that same object (no second list)."""
    from greenloop.methods.greenloop_seq import seqmatch
    assert seqmatch.DESCRIPTORS is F.SEQUENCE_DESCRIPTORS
    assert seqmatch.DESCRIPTORS == ("pixels", "pixels-patchnorm", "mobilenetv2", "gradients", "gradients+efficientnetlite0",
                                    "gradients+efficientnetlite0-int8")
    for name in seqmatch.DESCRIPTORS:
        assert F.BACKBONES[name].kind in F.EXTRACTORS
    assert set(F.EXTRACTORS) == {b.kind for b in F.BACKBONES.values()} | {"function"}   # no function registered yet


def test_patchnorm_and_gradients_entries(frames):
    """The two greenloop-seq descriptors as registry entries: computed from an independent cv2
    path (RGB -> gray, resize, / 255) and seqmatch's stage functions. The 96x72 frames shrink to
    32x32 (INTER_AREA) and are enlarged to 128 wide for gradients (INTER_LINEAR)."""
    def gray(size):
        interp = cv2.INTER_AREA if frames.shape[2] > size[0] else cv2.INTER_LINEAR
        g = [cv2.resize(cv2.cvtColor(f, cv2.COLOR_RGB2GRAY), size, interpolation=interp)
             for f in frames]
        return np.stack(g).astype(np.float32) / np.float32(255.0)
    P, ip = F.extract(frames, "pixels-patchnorm", progress=False, return_info=True)
    assert np.array_equal(P, F.patch_normalise(gray((32, 32))))
    assert ip.dim == 1024 and ip.weights == "none" and ip.input_size == (32, 32)
    # every 8x8 block of a patch-normalised frame: mean 0, std 1 (hand-checked definition)
    blocks = P[0].reshape(4, 8, 4, 8)
    assert np.allclose(blocks.mean(axis=(1, 3)), 0, atol=1e-5)
    assert np.allclose(blocks.std(axis=(1, 3)), 1, atol=1e-4)
    G_, ig = F.extract(frames, "gradients", progress=False, return_info=True)
    assert G_.shape == (len(frames), 256) and ig.input_size == (128, 64)
    assert np.array_equal(G_, F.gradient_histograms(gray((128, 64))))
    with pytest.raises(ValueError, match="has no weights"):
        F.extract(frames, "gradients", weights="imagenet")


def test_gray_float_frames_round_then_preprocess(frames):
    """Float frames in [0, 1] are rounded to uint8 and then take sequence.preprocess_image's path:
    the same descriptor as the uint8 frames they came from."""
    f = frames.astype(np.float32) / np.float32(255.0)
    assert np.array_equal(F.extract(f, "pixels", progress=False),
                          F.extract(frames, "pixels", progress=False))
    ref = np.stack([sequence.preprocess_image(im, (32, 32), gray=True, color="rgb") for im in frames])
    assert np.array_equal(F.extract(frames, "pixels", progress=False),
                          ref.reshape(len(frames), -1).astype(np.float32) / np.float32(255.0))


def test_extract_all_resolves_weights_once_per_entry(tiny_sequence, tmp_path, monkeypatch):
    """extract_all resolves each (backbone, weights) pair once, when it makes the Descriptor (the
    cache key, the random-init report and the extraction read it there)."""
    from greenloop.features import descriptor as FD
    calls = []

    def counting(name, weights, warn=True):
        calls.append(name)
        return real(name, weights, warn)
    real = FD.resolve
    monkeypatch.setattr(FD, "resolve", counting)
    F.extract_all(tiny_sequence, ["pixels", "sift_bovw"], step=5, vocab_size=8, cache=tmp_path)
    assert calls == ["pixels", "sift_bovw"]


@pytest.mark.filterwarnings("ignore:only .* SIFT descriptors")      # 8 small frames: a small vocabulary
@pytest.mark.parametrize("backbone", ["pixels", "gradients", "sift_bovw", "mobilenetv3small"])
def test_bgr_frames_give_the_rgb_frames_descriptors(frames, tmp_path, backbone):
    """color="bgr" (frames as cv2.imread decodes them, the streams' input) gives exactly the
    descriptors of the same frames in RGB, for the gray families and a CNN; a folder is decoded
    to RGB whatever color says; a wrong channel order changes a CNN descriptor."""
    bgr = np.ascontiguousarray(frames[..., ::-1])
    size = SIZE if backbone == "mobilenetv3small" else None
    rgb_x = F.extract(frames, backbone, None, progress=False, input_size=size)
    assert np.array_equal(F.extract(bgr, backbone, None, progress=False, input_size=size, color="bgr"), rgb_x)
    if backbone != "sift_bovw":   # (its vocabulary is fitted on the frames given)
        one = F.stack_frames([bgr[0]])            # one frame: a (1, H, W, 3) view, not a copy
        assert one.shape == (1, *bgr.shape[1:]) and np.shares_memory(one, bgr)
        assert np.allclose(F.extract(one, backbone, None, progress=False, input_size=size, color="bgr"),
                           rgb_x[:1], rtol=1e-4, atol=0)
    if backbone == "mobilenetv3small":
        assert not np.allclose(F.extract(bgr, backbone, None, progress=False, input_size=size), rgb_x,
                               rtol=1e-2, atol=0)
        folder = write_sequence(tmp_path / "seq", frames[:3])
        assert np.allclose(F.extract(folder, backbone, None, progress=False, input_size=size, color="bgr"),
                           F.extract(folder, backbone, None, progress=False, input_size=size), rtol=1e-4, atol=0)
    with pytest.raises(ValueError, match="color must be"):
        F.extract(frames, backbone, None, progress=False, color="hsv")


def test_run_model_warms_each_batch_length_up_once_per_key():
    """A stream describes one frame per call: with a warm_key the network runs once per frame after
    the first call of that batch length (not twice, warm-up and timed pass), without one it warms up
    every call, and the features are the same either way."""
    from greenloop.features import cnn
    calls = []

    def predict(x):
        calls.append(len(x))
        return x.reshape(len(x), -1).astype(np.float32) * 2

    frames = np.arange(12, dtype=np.float32).reshape(3, 2, 2)
    cnn.clear_models()
    first, _ = cnn.run_model(predict, frames[:1], lambda a: a, 32, False, "t", ("fake", 1))
    assert calls == [1, 1]                                         # warm-up, then the timed pass
    again, _ = cnn.run_model(predict, frames[1:2], lambda a: a, 32, False, "t", ("fake", 1))
    assert calls == [1, 1, 1] and np.array_equal(again, frames[1:2].reshape(1, -1) * 2)
    cnn.run_model(predict, frames, lambda a: a, 2, False, "t", ("fake", 1))     # lengths 2 and 1: only 2 is new
    assert calls == [1, 1, 1, 2, 2, 1]
    cnn.run_model(predict, frames[:1], lambda a: a, 32, False, "t")           # no key: warm-up every call
    assert calls[-2:] == [1, 1] and len(calls) == 8
    cnn.clear_models()                                             # the models go, and with them what was warmed
    cnn.run_model(predict, frames[:1], lambda a: a, 32, False, "t", ("fake", 1))
    assert calls[-2:] == [1, 1] and len(calls) == 10
    assert np.array_equal(first, frames[:1].reshape(1, -1) * 2)


def test_keras_predict_runs_the_lite_network_as_its_tflite_graph_with_the_same_outputs():
    """EfficientNet-Lite's Keras network runs as a TFLite graph (the runtime of the MobileNet graphs):
    its maps equal predict_on_batch's to float32 rounding at every batch length, with one output and
    with several in the model's order; a graph that does not give the model's outputs on the probe
    batch is refused; the Keras applications keep predict_on_batch."""
    from greenloop.features import layers as FL
    from greenloop.features.registry import get_backbone
    if keras.backend.backend() != "tensorflow":
        pytest.skip("the TFLite runtime is the tensorflow backend's")
    b = get_backbone("efficientnetlite0")
    names = tuple(FL.LAYERS["efficientnetlite0"][d][1] for d in ("early", "mid"))
    model = FL._keras_layers(b.name, None, (64, 32), names)          # random init, two maps
    predict = FCNN.predictor(b, model)
    assert predict != model.predict_on_batch
    x = FCNN._preprocess_fn(b)(np.random.default_rng(3).integers(0, 256, (3, 32, 64, 3)).astype(np.float32))
    for batch in (x[:1], x, x[:2]):
        want, got = model.predict_on_batch(batch), predict(batch)
        assert len(got) == 2 and [g.shape for g in got] == [np.asarray(w).shape for w in want]
        for w, g in zip(want, got):
            w = np.asarray(w)
            assert np.abs(g - w).max() <= 1e-4 * np.abs(w).max() and np.abs(w).max() > 0
    one = FL._keras_layers(b.name, None, (64, 32), names[1:])
    assert FCNN.keras_predict(one)(x).shape == np.asarray(one.predict_on_batch(x)).shape
    bad = keras.Model(one.inputs, one.outputs)
    bad.predict_on_batch = lambda a: np.asarray(one.predict_on_batch(a)) + 1.0
    with pytest.raises(RuntimeError, match="probe"):
        FCNN.keras_predict(bad)
    vgg = FCNN._cnn_model("vgg19", None, (64, 64))
    assert FCNN.predictor(get_backbone("vgg19"), vgg) == vgg.predict_on_batch


def test_a_network_is_converted_once_and_its_key_is_its_layers_and_weights(tmp_path, monkeypatch):
    """The same network in two objects gets one key and one converted graph, which the second
    loads instead of converting (a network built in another process too: the key leaves out the
    layer names Keras numbers per process); other weights, or other converter settings, get another key."""
    import tensorflow as tf

    from greenloop.features import layers as FL
    from greenloop.util import cache
    if keras.backend.backend() != "tensorflow":
        pytest.skip("the TFLite runtime is the tensorflow backend's")
    monkeypatch.setattr(cache, "CACHE_DIR", tmp_path)
    a = FL._keras_layers("efficientnetlite0", None, (32, 32), (FL.LAYERS["efficientnetlite0"]["mid"][1],))
    b, c = keras.models.clone_model(a), keras.models.clone_model(a)       # other objects, other variables
    b.set_weights(a.get_weights())
    c.set_weights([w * 1.01 for w in a.get_weights()])
    assert cache.model_key(a) == cache.model_key(b) != cache.model_key(c)
    assert cache.model_key(a) != cache.model_key(a, converter="another")
    small = [keras.Sequential([keras.Input((8, 8, 3)), keras.layers.Conv2D(4, 3), keras.layers.Flatten()]) for _ in "ab"]
    small[1].set_weights(small[0].get_weights())
    assert small[0].layers[0].name != small[1].layers[0].name                  # conv2d, conv2d_1
    assert cache.model_key(small[0]) == cache.model_key(small[1])
    converter, converted = tf.lite.TFLiteConverter.from_concrete_functions, []
    monkeypatch.setattr(tf.lite.TFLiteConverter, "from_concrete_functions",
                        lambda *args: converted.append(1) or converter(*args))
    x = np.random.default_rng(0).uniform(-1, 1, (2, 32, 32, 3)).astype(np.float32)
    for model, conversions in ((a, 1), (b, 1), (c, 2)):
        want = np.asarray(model.predict_on_batch(x))
        assert np.abs(FCNN.keras_predict(model)(x) - want).max() <= 1e-4 * np.abs(want).max()
        assert len(converted) == conversions
    assert len(list((tmp_path / cache.GRAPHS).glob("*/graph.tflite"))) == 2
