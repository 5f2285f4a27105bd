"""features.get -> Descriptor: dims and labels per family, values equal to the extraction before the
redesign, the one name grammar, and the one cache (hits, and keys that stayed what they were)."""
import hashlib
import json
import lzma
import os

import cv2
import numpy as np
import pytest

from greenloop import features as F
from greenloop.features import descriptor as FD
from greenloop.util import cache


@pytest.fixture(scope="module")
def frames():
    """6 blurred random RGB frames, 48 x 64 (the frames the checksums below were computed on)."""
    rng = np.random.default_rng(0)
    return np.stack([cv2.GaussianBlur(rng.integers(0, 256, (48, 64, 3), dtype=np.uint8), (5, 5), 2) for _ in range(6)])


@pytest.fixture()
def folder(tmp_path, frames):
    (tmp_path / "seq" / "rgb").mkdir(parents=True)
    for i, f in enumerate(frames):
        cv2.imwrite(str(tmp_path / "seq" / "rgb" / f"{i}.png"), f[..., ::-1])
    return tmp_path / "seq"


def _sha(X) -> str:
    return hashlib.sha1(np.ascontiguousarray(X).tobytes()).hexdigest()[:16]


@pytest.mark.filterwarnings("ignore:only .* SIFT descriptors")
@pytest.mark.parametrize("name, kw, dim, label", [
    ("pixels", {}, 1024, "pixels (none)"),
    ("pixels-patchnorm", dict(input_size=(64, 32)), 2048, "pixels-patchnorm (none)"),
    ("gradients", {}, 256, "gradients (none)"),
    ("sift_bovw", dict(vocab_size=16), 16, "sift_bovw (none)"),
    ("ghostnet:random", dict(input_size=32), 960, "ghostnet (random init)"),
    ("efficientnetlite0:random", dict(layer="mid", pooling="grid2"), 448, "efficientnetlite0@mid-grid2 (random init)"),
])
def test_each_family_states_its_dim_and_label(frames, name, kw, dim, label):
    d = F.get(name, **kw)
    X = d(frames)
    assert d.dim == dim and d.label == label and X.shape == (len(frames), dim) and X.dtype == np.float32


def test_the_main_papers_cnn_states_its_dim_from_the_model(frames):
    import keras
    model = keras.Sequential([keras.Input((32, 32, 1)), keras.layers.Conv2D(4, 3), keras.layers.Flatten(),
                              keras.layers.Dense(68, activation="relu"), keras.layers.Dense(5, activation="softmax")])
    d = F.get("spot_cnn", model)
    assert d.dim == 68 and d(frames).shape == (6, 68) and d.label == f"spot_cnn (model:{model.name})"


# sha1 (16 hex) of the (6, D) float32 rows the pre-redesign path gave on ``frames`` (features.extract
# at commit e88e966, computed before the old path was removed): the values must stay bit-identical,
# because the study's results are compared cell by cell and the descriptor cache keeps values under
# keys that no longer hash the code (util.cache.DESCRIPTOR_CODE_VERSION): a change here must bump it.
BEFORE = {"pixels": "03f1463a2a62768c", "pixels-patchnorm": "1113e3e17b215bf5", "gradients": "c7d3b9691a19b2df",
          "sift_bovw": "6f2d77b467381d0b"}


@pytest.mark.parametrize("name", sorted(BEFORE))
def test_values_equal_the_extraction_before_the_redesign(frames, folder, name):
    d = F.get(name, vocab_size=16)
    assert _sha(d(frames)) == BEFORE[name]
    assert _sha(d(np.ascontiguousarray(frames[..., ::-1]), color="bgr")) == BEFORE[name]      # cv2's channel order
    assert _sha(d.extract(folder)[0]) == BEFORE[name]                                        # a folder decodes to RGB


def test_cnn_values_equal_the_extraction_before_the_redesign(frames):
    """CNN rows to float32 rounding (their kernels may differ by CPU); the ImageNet one where its file is here."""
    X = F.get("ghostnet:random", input_size=32)(frames)
    np.testing.assert_allclose(X[0, :4], [2.5308072508778423e-06, 1.83472457138123e-05, 0.0, 1.6278216207865626e-05],
                               rtol=1e-4, atol=1e-10)
    if F.imagenet_weights_path("efficientnetlite0") is not None:
        X = F.get("efficientnetlite0", input_size=64)(frames)
        np.testing.assert_allclose(X.astype(np.float64).sum(1), [332.6163794777822, 482.1459357312415, 237.22975768038305,
                                                                 331.51022015244234, 389.42270575938164, 464.12009846416186],
                                   rtol=1e-4)


def test_an_unknown_name_lists_the_valid_ones():
    with pytest.raises(ValueError, match=r"unknown descriptor 'alexnet'; valid names: vgg19, .*pixels.*@<depth>-<pooling>"):
        F.get("alexnet")
    with pytest.raises(ValueError, match="suffix must be ':random' or ':imagenet'"):
        F.get("vgg19:pretrained")
    with pytest.raises(ValueError, match="backbone>@<depth>-<pooling>"):
        F.get("ghostnet@mid-avg")
    with pytest.raises(ValueError, match="fixed 224x224 input"):
        F.get("mobilenetv2", input_size=64)
    assert F.get("mobilenetv2", cnn_input_size=64).input_size == (224, 224)      # a study-wide CNN size: ignored
    assert "efficientnetlite0@last-gem" in F.names() and len(F.names()) == len(F.BACKBONES) + 27


def test_the_grammar_is_read_once():
    assert F.parse("mobilenetv2@mid-grid2:random") == ("mobilenetv2", "mid", "grid2", "random")
    assert F.parse("MobileNetV2").base == "mobilenetv2" and F.split_spec("resnet50:imagenet", None) == ("resnet50", "imagenet")
    d = F.get("mobilenetv2:random", "imagenet")             # the suffix wins over the weights argument
    assert d.resolved.label == "random init" and d.name == "mobilenetv2:random" and d.parsed.base == "mobilenetv2"
    assert F.get("efficientnetlite0", None, layer="early").parsed.base == "efficientnetlite0@early-avg"


def test_the_cache_hits_on_a_second_call(folder, tmp_path, monkeypatch):
    d = F.get("sift_bovw", vocab_size=16)
    X, info = d.describe(folder, step=2, cache=tmp_path / "c")
    assert len(list((tmp_path / "c").glob("sift_bovw-*/features.npy"))) == 1

    def fail(*a, **k):
        raise AssertionError("recomputed a cached descriptor")
    monkeypatch.setitem(FD.EXTRACTORS, "sift_bovw", fail)
    Y, again = d.describe(folder, step=2, cache=tmp_path / "c")
    assert np.array_equal(X, Y) and again.label == info.label and again.seconds_per_image == info.seconds_per_image
    assert np.array_equal(again.extra["vocabulary"], info.extra["vocabulary"]) and again.input_size == info.input_size
    with pytest.raises(AssertionError, match="recomputed"):
        d.describe(folder, step=3, cache=tmp_path / "c")                           # other settings: another key


def test_keys_are_the_keys_of_the_code_before(tmp_path):
    """descriptor_key hashes the frozen stamp of the descriptor code at e5611eb, so the keys (and the
    warm cache) are those the old live-code hash gave: this one was computed by that code."""
    path, digest = cache._STAMP_V1
    assert hashlib.sha1(lzma.decompress(path.read_bytes())).hexdigest() == digest == hashlib.sha1(cache.code_stamp()).hexdigest()
    frames = []
    for i in range(3):
        p = tmp_path / f"{i}.png"
        p.write_bytes(b"x" * (10 * (i + 1)))
        os.utime(p, ns=(10 ** 18 + i, 10 ** 18 + i))
        frames.append(p)
    meta = dict(backbone="mobilenetv2", source=["/w/mobilenet_v2_1.0_224_quant.tflite", 1700000000000000000],
                input_size=None, step=4, vocab_size=None, folder="/data/seq", keras="3.0.0")
    assert cache.descriptor_key("mobilenetv2", frames, meta) == "mobilenetv2-4215ea68045434f7"


def test_a_descriptor_keys_only_the_settings_keys_always_held(folder):
    import keras
    meta = F.get("ghostnet:random", cnn_input_size=128)._key_meta(folder, 4)
    assert meta == dict(backbone="ghostnet", source=None, input_size=128, step=4, vocab_size=None,
                        folder=str(folder.resolve()), keras=keras.__version__)
    assert json.dumps(F.get("pixels", cnn_input_size=128)._key_meta(folder, 1)["input_size"]) == "null"
    assert F.get("pixels", input_size=64)._key_meta(folder, 1)["size"] == [64, 64]      # not the 32x32 entry
