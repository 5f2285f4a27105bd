"""PyTorch-trained weights for the Keras ports (greenloop.backbones.ghostnet, greenloop.backbones.efficientnet_lite), no torch.

Three things every port needs, in one place:

* naming: a Keras layer is named after the torch module path that holds its weights, with ``.``
  written ``__`` (Keras's torch backend forbids dots): ``_blocks.3._expand_conv`` <->
  ``_blocks__3___expand_conv`` (``keras_layer_name`` / ``torch_module_path``; the replacement is
  left to right, so the mapping is reversible as long as a torch path never contains ``__``).
* layouts: ``load_state_dict`` / ``export_state_dict`` move a torch ``state_dict`` (name -> numpy
  array in torch layouts: conv (O, I, kh, kw), depthwise (C, 1, kh, kw), linear (out, in)) into or
  out of such a model, checking every name and shape.
* files: ``read_checkpoint`` reads a ``torch.save`` file (the zip format of torch >= 1.6 and the
  older sequential-pickle format) into numpy arrays WITHOUT importing torch. Its unpickler is
  restricted: it builds only ``collections.OrderedDict``, tensors (``torch._utils._rebuild_tensor*``,
  ``_rebuild_parameter``) and typed storages; any other global in the file (a class, a function
  such as ``os.system``) raises ``ValueError`` before anything runs.
"""
from __future__ import annotations

import pickle
import struct
import zipfile
from collections import OrderedDict
from dataclasses import dataclass
from pathlib import Path

import numpy as np

# typed storage classes of torch and the numpy dtype of their elements (bfloat16 has no numpy type)
STORAGE_DTYPES = {
    "FloatStorage": np.float32, "DoubleStorage": np.float64, "HalfStorage": np.float16,
    "LongStorage": np.int64, "IntStorage": np.int32, "ShortStorage": np.int16,
    "CharStorage": np.int8, "ByteStorage": np.uint8, "BoolStorage": np.bool_,
}
LEGACY_MAGIC = 0x1950A86A20F9469CFC6C   # first pickle of a pre-zip torch.save file
SKIP_SUFFIXES = ("num_batches_tracked",)  # BatchNorm counters: in a state_dict, not in Keras


# --------------------------------------------------------------------------------------------
# names and layouts
# --------------------------------------------------------------------------------------------

def keras_layer_name(torch_path: str) -> str:
    """Keras layer name of a torch module path: dots become double underscores
    (``blocks.3.0.se.conv_reduce`` -> ``blocks__3__0__se__conv_reduce``)."""
    return torch_path.replace(".", "__")


def torch_module_path(keras_name: str) -> str:
    """Inverse of ``keras_layer_name``."""
    return keras_name.replace("__", ".")


def param_map(model):
    """For every weight of ``model``: (torch key, keras variable, kind).

    kind says how to convert the torch array into the Keras one: 'conv' (O,I,kh,kw)->(kh,kw,I,O),
    'dw' (C,1,kh,kw)->(kh,kw,C,1), 'dense' (out,in)->(in,out), 'vec' 1-D as is. Raises ValueError
    for a layer with weights of another type (no torch mapping).
    """
    import keras
    L = keras.layers
    out = []
    for layer in model.layers:
        n = torch_module_path(layer.name)
        if isinstance(layer, L.DepthwiseConv2D):
            out.append((f"{n}.weight", layer.kernel, "dw"))
        elif isinstance(layer, L.Conv2D):
            out.append((f"{n}.weight", layer.kernel, "conv"))
            if layer.use_bias:
                out.append((f"{n}.bias", layer.bias, "vec"))
        elif isinstance(layer, L.BatchNormalization):
            out += [(f"{n}.weight", layer.gamma, "vec"), (f"{n}.bias", layer.beta, "vec"),
                    (f"{n}.running_mean", layer.moving_mean, "vec"),
                    (f"{n}.running_var", layer.moving_variance, "vec")]
        elif isinstance(layer, L.Dense):
            out += [(f"{n}.weight", layer.kernel, "dense"), (f"{n}.bias", layer.bias, "vec")]
        elif layer.weights:
            raise ValueError(f"layer {n} ({type(layer).__name__}) has weights but no torch mapping")
    return out


def to_torch(a: np.ndarray, kind: str) -> np.ndarray:
    """A Keras weight array in torch layout (see ``param_map`` for the kinds)."""
    if kind == "conv":
        return a.transpose(3, 2, 0, 1)
    if kind in ("dw", "dense"):
        return a.transpose(2, 3, 0, 1) if kind == "dw" else a.T
    return a


def to_keras(a: np.ndarray, kind: str) -> np.ndarray:
    """A torch weight array in Keras layout (inverse of ``to_torch``)."""
    if kind == "conv":
        return a.transpose(2, 3, 1, 0)
    if kind in ("dw", "dense"):
        return a.transpose(2, 3, 0, 1) if kind == "dw" else a.T
    return a


def export_state_dict(model) -> dict[str, np.ndarray]:
    """The weights of a ported model as a torch ``state_dict`` (numpy float32, torch layouts), with
    each BatchNorm's ``num_batches_tracked`` (int64 scalar 0) as torch writes it."""
    import keras
    sd = {k: np.ascontiguousarray(to_torch(np.asarray(v.numpy()), kind)).astype(np.float32)
          for k, v, kind in param_map(model)}
    for layer in model.layers:
        if isinstance(layer, keras.layers.BatchNormalization):
            sd[f"{torch_module_path(layer.name)}.num_batches_tracked"] = np.zeros((), np.int64)
    return sd


def load_state_dict(model, state: dict, arch: str, hint: str, head_prefixes=()) -> None:
    """Load a torch state dict (name -> numpy array, torch layouts) into a ported Keras model.

    Every weight of the model must be in ``state`` with the torch shape. ``num_batches_tracked``
    entries are ignored, and so are keys starting with ``head_prefixes`` when the model has none of
    them (a headless model loads a full checkpoint). arch (e.g. "timm's ghostnet_100") and hint
    (where to get the right file) go into the errors. Raises ValueError naming missing, unexpected
    or mis-shaped tensors, so a checkpoint of another architecture fails instead of loading garbage.
    Nothing is assigned unless everything fits.
    """
    pairs = param_map(model)
    expected = {k for k, _, _ in pairs}
    has_head = any(k.startswith(tuple(head_prefixes)) for k in expected) if head_prefixes else True
    unexpected = [k for k in state if k not in expected and not k.endswith(SKIP_SUFFIXES)
                  and (has_head or not k.startswith(tuple(head_prefixes)))]
    missing = [k for k in expected if k not in state]
    if missing or unexpected:
        raise ValueError(
            f"these weights are not {arch}: {len(missing)} tensors missing (e.g. {missing[:3]}), "
            f"{len(unexpected)} unexpected (e.g. {unexpected[:3]}); {hint}")
    values = []
    for key, var, kind in pairs:
        a = to_keras(np.asarray(state[key], dtype=np.float32), kind)
        if tuple(a.shape) != tuple(var.shape):
            raise ValueError(
                f"weight {key} has shape {tuple(np.asarray(state[key]).shape)} in the file but "
                f"{arch} needs {tuple(to_torch(np.zeros(var.shape), kind).shape)}: the file is for "
                f"another architecture or width; {hint}")
        values.append(a)
    for (_, var, _), a in zip(pairs, values):
        var.assign(a)


# --------------------------------------------------------------------------------------------
# torch.save files without torch
# --------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class _Storage:
    key: str
    dtype: type


@dataclass(frozen=True)
class _Tensor:
    """A tensor waiting for its storage's bytes: offset, size and stride in elements."""
    storage: _Storage
    offset: int
    size: tuple
    stride: tuple


def _rebuild_tensor(storage, storage_offset, size, stride, *_):
    return _Tensor(storage, int(storage_offset), tuple(size), tuple(stride))


def _rebuild_parameter(data, *_):
    return data


class _CheckpointUnpickler(pickle.Unpickler):
    """Builds OrderedDicts, tensors and storages; refuses every other global."""

    _ALLOWED = {("collections", "OrderedDict"): OrderedDict,
                ("torch._utils", "_rebuild_tensor_v2"): _rebuild_tensor,
                ("torch._utils", "_rebuild_tensor"): _rebuild_tensor,
                ("torch._utils", "_rebuild_parameter"): _rebuild_parameter}

    def find_class(self, module, name):
        if (module, name) in self._ALLOWED:
            return self._ALLOWED[module, name]
        if module == "torch" and name in STORAGE_DTYPES:
            return STORAGE_DTYPES[name]
        raise pickle.UnpicklingError(
            f"refusing to load {module}.{name}: a weights checkpoint holds only tensors (this file "
            f"may run code when unpickled)")

    def persistent_load(self, pid):
        # zip: ('storage', type, key, location, numel); legacy: (..., numel, view_metadata)
        if not (isinstance(pid, tuple) and len(pid) in (5, 6) and pid[0] == "storage"):
            raise pickle.UnpicklingError(f"unexpected persistent id {pid!r} in a torch checkpoint")
        if len(pid) == 6 and pid[5] is not None:
            raise pickle.UnpicklingError("storage views (torch < 0.4 checkpoints) are not supported")
        dtype = pid[1]
        if dtype not in STORAGE_DTYPES.values():
            raise pickle.UnpicklingError(f"unsupported storage type {dtype!r}")
        return _Storage(str(pid[2]), dtype)


def _unpickle(f):
    return _CheckpointUnpickler(f, encoding="utf-8").load()


def _tensor_array(t: _Tensor, buffers: dict) -> np.ndarray:
    base = buffers.get(t.storage.key)
    if base is None:
        raise ValueError(f"storage {t.storage.key} is missing from the checkpoint")
    if np.prod(t.size, dtype=np.int64) == 0:
        return np.zeros(t.size, t.storage.dtype)
    last = t.offset + sum((n - 1) * s for n, s in zip(t.size, t.stride))
    if t.offset < 0 or min(t.stride, default=0) < 0 or last >= len(base):
        raise ValueError(f"a tensor reaches past its storage {t.storage.key}: corrupt checkpoint")
    item = base.itemsize
    view = np.lib.stride_tricks.as_strided(base[t.offset:], shape=t.size,
                                           strides=[s * item for s in t.stride])
    return np.array(view)  # own, contiguous copy


def _read_zip(path: Path):
    with zipfile.ZipFile(path) as z:
        pkl = [n for n in z.namelist() if n.endswith("/data.pkl") or n == "data.pkl"]
        if len(pkl) != 1:
            raise ValueError(f"{path} is a zip file but not a torch checkpoint (no single data.pkl)")
        prefix = pkl[0][: -len("data.pkl")]
        order = z.read(prefix + "byteorder").decode().strip() if prefix + "byteorder" in \
            z.namelist() else "little"
        with z.open(pkl[0]) as f:
            obj = _unpickle(f)
        keys = {t.storage for t in _tensors(obj)}
        buffers = {}
        for s in keys:
            raw = z.read(f"{prefix}data/{s.key}")
            buffers[s.key] = np.frombuffer(raw, dtype=np.dtype(s.dtype).newbyteorder(
                "<" if order == "little" else ">"))
    return obj, buffers


def _read_legacy(path: Path):
    with open(path, "rb") as f:
        if _unpickle(f) != LEGACY_MAGIC:
            raise ValueError(f"{path} is neither a zip nor a legacy torch.save checkpoint")
        _unpickle(f)                                  # protocol version
        info = _unpickle(f)                           # sys info: byte order, type sizes
        obj = _unpickle(f)
        keys = _unpickle(f)                           # storage keys, in the order their bytes follow
        dtypes = {t.storage.key: t.storage.dtype for t in _tensors(obj)}
        little = info.get("little_endian", True) if isinstance(info, dict) else True
        buffers = {}
        for key in keys:
            (numel,) = struct.unpack("<q" if little else ">q", f.read(8))
            dtype = np.dtype(dtypes.get(key, np.uint8)).newbyteorder("<" if little else ">")
            raw = f.read(numel * dtype.itemsize)
            if len(raw) != numel * dtype.itemsize:
                raise ValueError(f"{path} ends inside storage {key}: truncated checkpoint")
            buffers[key] = np.frombuffer(raw, dtype=dtype)
    return obj, buffers


def _tensors(obj):
    if not isinstance(obj, dict):
        raise ValueError(f"the checkpoint holds a {type(obj).__name__}, not a state_dict "
                         f"(name -> tensor)")
    return [v for v in obj.values() if isinstance(v, _Tensor)]


def read_checkpoint(path) -> dict[str, np.ndarray]:
    """Read a PyTorch ``state_dict`` file (``torch.save``, zip or legacy format) without torch.

    path: a ``.pth``/``.pt`` file holding a flat mapping name -> tensor. Returns name -> numpy array
    (dtype and shape as torch.load gives them; native byte order; C-contiguous copies). Raises
    FileNotFoundError if the file is missing and ValueError if it is not a torch checkpoint, holds
    anything but tensors (the restricted unpickler refuses other globals: nothing in it is run) or
    is truncated.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"torch checkpoint {path} not found")
    try:
        obj, buffers = _read_zip(path) if zipfile.is_zipfile(path) else _read_legacy(path)
    except (pickle.UnpicklingError, EOFError, KeyError, struct.error, UnicodeDecodeError) as e:
        raise ValueError(f"{path} is not a readable torch state_dict checkpoint: {e}") from e
    out = {}
    for k, v in obj.items():
        if not isinstance(v, _Tensor):
            raise ValueError(f"{path}: entry {k!r} is a {type(v).__name__}, not a tensor: only "
                             f"state_dict files (name -> tensor) can be read")
        out[str(k)] = _tensor_array(v, buffers).astype(np.dtype(v.storage.dtype), copy=False)
    return out
