"""Policy files: a JSON spec (:class:`PolicySpec`) and an ``.npz`` of weights, read as data.

A policy file is data, never code: the weights are read with
``allow_pickle=False``, and every array's name, dtype, shape and values are
checked against the spec; a file that does not fit is one
:class:`~dfcoa_opt.core.errors.ScenarioError` naming the file and the key or array.
:func:`load_policy` gives the network (:class:`LoadedPolicy`), whose compiled
kernel sums in a fixed order per row, and :func:`policy_digest` the SHA-256 of
both files. The controllers that run them are in :mod:`dfcoa_opt.control.policy.controller`;
the format is in ``docs/policies.md``.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import zipfile
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numba
import numpy as np
from numpy.typing import NDArray

from dfcoa_opt.control.features import ObservationSpec
from dfcoa_opt.core.errors import DfcoaError, ScenarioError
from dfcoa_opt.core.params import build, param
from dfcoa_opt.world.robots.models import CommandKind

FloatArray = NDArray[np.float64]
#: The ``format`` value of every policy spec, and the version this code reads.
FORMAT, VERSION = "dfcoa-policy", 1
#: Controller id prefix of a policy file.
PREFIX = "policy:"
#: Activation names, in the order of the kernel's codes.
ACTIVATIONS = ("linear", "relu", "tanh", "sigmoid", "elu", "silu", "softplus")
Activation = Literal["linear", "relu", "tanh", "sigmoid", "elu", "silu", "softplus"]
Frame = Literal["body", "world"]
_FLOATS = (np.dtype(np.float32), np.dtype(np.float64))
_PICKLED = "holds Python objects (pickled data); refused"


@dataclass(frozen=True)
class LayerSpec:
    """One dense layer ``y = activation(W x + b)``, ``W`` of shape (size, inputs)."""

    size: int = param(doc="Outputs of the layer; the last layer's is 2 (the command).",
                      ge=1, le=4096)
    activation: Activation = param("linear", doc="Elementwise activation.")


@dataclass(frozen=True)
class PolicySpec:
    """The JSON spec of a policy file (``docs/policies.md``)."""

    format: str = param(doc="Always 'dfcoa-policy'.")
    version: int = param(doc="Format version (1).", ge=1)
    command: CommandKind = param(doc="Kind of the action rows: unicycle (v m/s, omega rad/s), "
                                     "velocity (vx, vy m/s) or acceleration (ax, ay m/s^2).")
    layers: tuple[LayerSpec, ...] = param(doc="The dense layers, input first.")
    action_scale: tuple[float, float] = param(doc="command = offset + scale * output, per "
                                                  "column, in the command's units.", gt=0.0)
    observation: ObservationSpec = param(doc="The input vector; every field is required.")
    weights: str = param("", doc="The .npz, relative to the spec's folder; default: the "
                                 "spec's name with .npz.")
    frame: Frame | None = param(None, doc="Frame of a velocity or acceleration action, "
                                          "required for one: world (as the environments "
                                          "apply actions) or body (x forward, y left).")
    action_offset: tuple[float, float] = param((0.0, 0.0), doc="Added after scaling, in the "
                                                               "command's units.")
    clip: bool = param(False, doc="Clip the output to [-1, 1] before scaling.")
    normalize: bool = param(False, doc="Standardize the input with arrays obs_mean and "
                                       "obs_std (> 0) of the .npz: (x - mean) / std.")

    def check(self, src: str, prefix: str) -> None:
        """Checks across keys (called by :func:`~dfcoa_opt.core.params.build`)."""
        if not self.layers:
            raise ScenarioError(src, "layers", "needs at least one layer")
        if self.layers[-1].size != 2:
            raise ScenarioError(src, f"layers[{len(self.layers) - 1}].size",
                                f"the last layer gives the 2 command columns, got "
                                f"{self.layers[-1].size}")
        if self.command == "unicycle" and self.frame == "world":
            raise ScenarioError(src, "frame", "a unicycle command (v, omega) has no world "
                                              "frame; leave frame out")
        if self.command != "unicycle" and self.frame is None:
            raise ScenarioError(src, "frame", f"is required for a {self.command} command: "
                                "'world' (as the environments apply actions) or 'body' (x "
                                "forward, y left, rotated by the heading)")


@dataclass(frozen=True)
class LoadedPolicy:
    """A validated policy file: its spec and float64 weights.

    Attributes:
        spec: The JSON spec.
        layers: ``(W (size, inputs), b (size,), activation code)`` per layer.
        mean: ``(D,)`` input mean with ``normalize``, else None.
        std: ``(D,)`` input standard deviation with ``normalize``, else None.
        files: The JSON and the ``.npz``.
    """

    spec: PolicySpec
    layers: tuple[tuple[FloatArray, FloatArray, int], ...]
    mean: FloatArray | None
    std: FloatArray | None
    files: tuple[Path, Path]

    def forward(self, x: FloatArray) -> FloatArray:
        """Actions ``(R, 2)`` in command units (policy frame) for inputs ``(R, D)``."""
        if self.mean is not None and self.std is not None:
            x = (x - self.mean) / self.std
        y = np.ascontiguousarray(x, dtype=np.float64)
        for w, b, act in self.layers:
            y = _dense(y, w, b, act)
        if self.spec.clip:
            y = np.clip(y, -1.0, 1.0)
        return np.asarray(self.spec.action_offset) + np.asarray(self.spec.action_scale) * y


@numba.njit(cache=True)
def _dense(x: FloatArray, w: FloatArray, b: FloatArray, act: int) -> FloatArray:  # pragma: no cover
    """``(R, H)`` = activation ``act`` (:data:`ACTIVATIONS`) of ``x (R, D) @ w (H, D).T + b``.

    Each sum runs in input order, so a row's result never depends on R.
    """
    r, d = x.shape
    h = w.shape[0]
    out = np.empty((r, h))
    for i in range(r):
        for j in range(h):
            s = b[j]
            for k in range(d):
                s += w[j, k] * x[i, k]
            if act == 1:
                s = max(s, 0.0)
            elif act == 2:
                s = math.tanh(s)
            elif act == 3:
                s = 1.0 / (1.0 + math.exp(-s))
            elif act == 4:
                s = s if s > 0.0 else math.expm1(s)
            elif act == 5:
                s = s / (1.0 + math.exp(-s))
            elif act == 6:
                s = max(s, 0.0) + math.log1p(math.exp(-abs(s)))
            out[i, j] = s
    return out


def _unique_keys(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    """``json`` object hook refusing a key given twice (the later one would win silently)."""
    out: dict[str, Any] = {}
    for k, v in pairs:
        if k in out:
            raise ValueError(f"key '{k}' is given twice")
        out[k] = v
    return out


def _read_spec(path: Path) -> PolicySpec:
    """The validated JSON spec of a policy file."""
    src = str(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ScenarioError(src, "", "policy file not found") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ScenarioError(src, "", f"cannot read the policy file: {exc}") from None
    try:
        data = json.loads(text, object_pairs_hook=_unique_keys)
    except (ValueError, RecursionError) as exc:
        raise ScenarioError(src, "", f"not valid JSON: {exc}") from None
    if not isinstance(data, dict):
        raise ScenarioError(src, "", f"must be a JSON object (a policy spec), got "
                                     f"{type(data).__name__}")
    if data.get("format") != FORMAT:
        raise ScenarioError(src, "format", f"must be '{FORMAT}', got {data.get('format')!r}")
    if type(data.get("version")) is not int or data["version"] != VERSION:
        raise ScenarioError(src, "version", f"unsupported version {data.get('version')!r}; "
                                            f"this toolkit reads version {VERSION}")
    spec = build(PolicySpec, data, src)
    for f in dataclasses.fields(ObservationSpec):
        if f.name not in data["observation"]:
            raise ScenarioError(src, f"observation.{f.name}", "is required in a policy file "
                                "(its input must not change with the defaults)")
    return spec


def _weights_path(path: Path, spec: PolicySpec) -> Path:
    """The ``.npz`` a spec names (relative to the spec's folder)."""
    return path.parent / (spec.weights or path.with_suffix(".npz").name)


def _pickled(exc: Exception) -> str:
    """The refusal of pickled data when numpy's error is about it, else ""."""
    text = str(exc).lower()
    return _PICKLED if "pickle" in text or "object arrays" in text else ""


def _array(z: Any, name: str, shape: tuple[int, ...]) -> FloatArray:
    """Array ``name`` of an open ``.npz`` (``allow_pickle=False``), checked, as float64."""
    arr = z[name]  # ValueError for an object (pickled) array, which is never unpickled
    if not isinstance(arr, np.ndarray):
        raise ValueError("not a .npy array")
    if arr.dtype.hasobject:
        raise ValueError(_PICKLED)
    if arr.dtype not in _FLOATS:
        raise ValueError(f"dtype {arr.dtype}, expected float32 or float64")
    if arr.shape != shape:
        raise ValueError(f"shape {arr.shape}, expected {shape}")
    if not np.isfinite(arr).all():
        raise ValueError("holds NaN or inf")
    return np.ascontiguousarray(arr, dtype=np.float64)


def _read_weights(path: Path, expected: dict[str, tuple[int, ...]],
                  spec_name: str) -> dict[str, FloatArray]:
    """Every expected array of the ``.npz`` (:func:`_array`), named and shaped as the spec says."""
    src = str(path)
    try:
        with open(path, "rb") as fh:
            magic = fh.read(6)
    except OSError as exc:
        gone = isinstance(exc, FileNotFoundError)
        raise ScenarioError(src, "", f"weights file not found (named by {spec_name})" if gone
                            else f"cannot read the weights file: {exc}") from None
    if not magic.startswith(b"PK"):
        raise ScenarioError(src, "", "is one .npy array, not an .npz archive of named arrays"
                            if magic == b"\x93NUMPY" else _PICKLED if magic[:1] == b"\x80"
                            else "not an .npz archive (no zip header)")
    try:
        z = np.load(path, allow_pickle=False)
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as exc:
        raise ScenarioError(src, "", _pickled(exc) or f"not an .npz archive of arrays: "
                                                       f"{exc}") from None
    with z:
        missing = [n for n in expected if n not in z.files]
        extra = sorted(set(z.files) - set(expected))
        if missing or extra:
            word = "missing" if missing else "unexpected"
            raise ScenarioError(src, (missing or extra)[0], f"{word} array; {spec_name} "
                                f"needs {', '.join(expected)}")
        out = {}
        for name, shape in expected.items():
            try:
                out[name] = _array(z, name, shape)
            except (OSError, ValueError, EOFError, KeyError, zipfile.BadZipFile,
                    zlib.error) as exc:
                raise ScenarioError(src, name, _pickled(exc) or str(exc)) from None
    return out


def load_policy(path: str | Path) -> LoadedPolicy:
    """Read and check a policy file (``path``: the JSON spec) and its ``.npz`` of weights.

    Raises:
        ScenarioError: One line naming the file and the key or array: a missing
            or unreadable file, bad JSON, a bad key, a missing or extra array,
            a wrong dtype or shape, NaN/inf, an object (pickled) array.
    """
    path = Path(path)
    spec = _read_spec(path)
    expected: dict[str, tuple[int, ...]] = {}
    inputs = spec.observation.size
    for i, layer in enumerate(spec.layers):
        expected[f"W{i}"], expected[f"b{i}"] = (layer.size, inputs), (layer.size,)
        inputs = layer.size
    if spec.normalize:
        expected["obs_mean"] = expected["obs_std"] = (spec.observation.size,)
    npz = _weights_path(path, spec)
    arrays = _read_weights(npz, expected, str(path))
    if spec.normalize and not (arrays["obs_std"] > 0.0).all():
        raise ScenarioError(str(npz), "obs_std", "must be > 0 everywhere")
    layers = tuple((arrays[f"W{i}"], arrays[f"b{i}"], ACTIVATIONS.index(layer.activation))
                   for i, layer in enumerate(spec.layers))
    return LoadedPolicy(spec, layers, arrays.get("obs_mean"), arrays.get("obs_std"),
                        (path, npz))


def policy_digest(path: str | Path) -> str:
    """SHA-256 of a policy's spec and ``.npz`` bytes, read anew (an unreadable file: missing)."""
    path = Path(path)
    try:
        files = [path, _weights_path(path, _read_spec(path))]
    except DfcoaError:
        files = [path]
    h = hashlib.sha256()
    for f in files:
        data = f.read_bytes() if f.is_file() else b"<missing>"
        h.update(len(data).to_bytes(8, "little") + data)
    return h.hexdigest()
