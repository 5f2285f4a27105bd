"""greenloop.features.layers: CNN maps at three depths, pooled three ways, and their names
("backbone@depth-pooling") in features.get / extract_all."""
import numpy as np
import pytest

from greenloop import features
from greenloop.features import layers


def test_pooling_of_a_known_map():
    fmap = np.zeros((1, 4, 4, 2), np.float32)
    fmap[0, :2, :2, 0] = 4.0          # top-left quadrant, channel 0
    fmap[0, 2:, 2:, 1] = -8.0         # bottom-right quadrant, channel 1 (negative: a linear bottleneck)
    assert np.allclose(layers.pool(fmap, "avg"), [[1.0, -2.0]])
    # 2 x 2 cells in row-major order, each L2-normalised: TL (1, 0), TR 0, BL 0, BR (0, -1)
    assert np.allclose(layers.pool(fmap, "grid2"), [[1, 0, 0, 0, 0, 0, 0, -1]])
    # GeM p = 3 clips at 1e-6: channel 0 is (mean of 4^3 over a quarter)^(1/3) = 4 / 4^(1/3); channel 1 ~ 1e-6
    assert np.allclose(layers.pool(fmap, "gem"), [[4.0 / 4 ** (1 / 3), 1e-6]], rtol=1e-4)
    with pytest.raises(ValueError, match="at least 2 x 2"):
        layers.pool(fmap[:, :1, :1], "grid2")
    with pytest.raises(ValueError, match="pooling must be"):
        layers.pool(fmap, "max")


def test_names_and_sizes():
    assert features.layer_name("mobilenetv2", "mid", "grid2") == "mobilenetv2@mid-grid2"
    assert features.parse("mobilenetv2@mid-grid2") == ("mobilenetv2", "mid", "grid2", "")
    assert features.parse("pixels") == ("pixels", None, None, "")
    with pytest.raises(ValueError, match="backbone>@<depth>-<pooling"):
        features.parse("mobilenetv2@middle-avg")
    s = layers.specs(["efficientnetlite0:random"])
    assert len(s) == 9 and s[0] == "efficientnetlite0@early-avg:random" and s[-1] == "efficientnetlite0@last-gem:random"
    assert features.split_spec(s[0]) == ("efficientnetlite0@early-avg", None)
    assert layers.aspect_size(64, 32) == (224, 112) and layers.aspect_size(160, 120) == (224, 176)
    assert layers.aspect_size(960, 540) == (224, 128) and layers.aspect_size(400, 20) == (224, 16)


@pytest.fixture(scope="module")
def frames():
    return np.random.default_rng(0).integers(0, 256, (4, 40, 80, 3), dtype=np.uint8)


def test_one_pass_gives_every_depth_and_the_last_map_is_the_plain_descriptor(frames):
    feats, info = layers.extract_layers(frames, "efficientnetlite0", None, progress=False)
    assert info["weights"] == "random init" and info["input"] == "224x112"      # 2:1 frames keep 2:1
    C = {"early": 40, "mid": 112, "last": 1280}
    assert {k: v.shape for k, v in feats.items()} == {(d, p): (4, C[d] * (4 if p == "grid2" else 1))
                                                      for d in layers.DEPTHS for p in layers.POOLINGS}
    square, _ = layers.extract_layers(frames, "efficientnetlite0", None, ("last",), ("avg",), aspect=False, progress=False)
    plain = features.extract(frames, "efficientnetlite0", None, progress=False)
    assert np.allclose(square[("last", "avg")], plain, atol=1e-5)
    d = features.get("efficientnetlite0@mid-grid2:random")
    X, i = d.extract(frames)
    assert np.allclose(X, feats[("mid", "grid2")], atol=1e-5) and d.dim == X.shape[1] == 448 and i.label == "efficientnetlite0@mid-grid2 (random init)"
    assert i.layer == "_blocks__10___add, grid2 pooling" and i.input_size == (224, 112)
    with pytest.raises(ValueError, match="layer descriptors exist for"):
        layers.extract_layers(frames, "ghostnet", None)


def test_extract_all_runs_one_cached_pass_per_network(tmp_path, frames):
    import cv2
    rgb = tmp_path / "seq" / "rgb"
    rgb.mkdir(parents=True)
    for k, f in enumerate(frames):
        cv2.imwrite(str(rgb / f"{k}.png"), f[..., ::-1])
    specs = ["efficientnetlite0@early-avg:random", "efficientnetlite0@last-grid2:random"]
    feats, infos = features.extract_all(tmp_path / "seq", specs, cache=tmp_path / "cache")
    assert len(list((tmp_path / "cache").glob("layers-*/layers.npz"))) == 1       # one pass for both entries
    again, _ = features.extract_all(tmp_path / "seq", specs[::-1], cache=tmp_path / "cache")
    assert all(np.array_equal(feats[s], again[s]) for s in specs)
    direct = features.get(specs[1])(tmp_path / "seq")
    assert np.allclose(direct, feats[specs[1]], atol=1e-5) and infos[specs[0]].dim == 40


def test_a_streams_frame_describer_reads_the_layer_entry(frames):
    """detect / the leaderboard's timed path: one BGR frame -> the same vector as the entry's batch."""
    from greenloop.methods.greenloop_seq import entry as greenloop_seq
    f = np.ascontiguousarray(frames[0][..., ::-1])                  # as cv2 decodes it
    one = greenloop_seq.frame_describer("efficientnetlite0@early-grid2", None)(f)
    batch = features.get("efficientnetlite0@early-grid2", None)(frames)
    assert one.shape == (160,) and np.allclose(one, batch[0], atol=1e-5)
