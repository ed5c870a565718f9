"""A small tanh MLP in numpy, trained by Adam on the mean squared error.

Deterministic: the initial weights and the minibatch order come from one
``numpy.random.Generator``, and every step is plain numpy (OpenBLAS under
``@``, whose kernels ``import dfcoa_opt`` pins, ``dfcoa_opt/core/runtime/dispatch.py``), so
the same data and seed give the same weights, bit for bit. OpenBLAS rounds
differently on different thread counts (measured: 1 and 2 threads differ in the
last bits after a few epochs), so :func:`one_blas_thread` runs the training on
one thread, whatever the machine's core count.

The layers are stored as the policy file stores them (``docs/policies.md``):
``W{i}`` of shape (outputs, inputs), ``b{i}`` of shape (outputs,); hidden
layers are ``tanh``, the last one is linear.
"""

from __future__ import annotations

import contextlib
import ctypes
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
#: ``[(W (out, in), b (out,)), ...]``, input layer first.
Layers = list[tuple[FloatArray, FloatArray]]


#: OpenBLAS's thread setters and getters, by the names numpy's and scipy's builds export.
_BLAS_THREADS = (("scipy_openblas_set_num_threads64_", "scipy_openblas_get_num_threads64_"),
                 ("scipy_openblas_set_num_threads", "scipy_openblas_get_num_threads"),
                 ("openblas_set_num_threads64_", "openblas_get_num_threads64_"),
                 ("openblas_set_num_threads", "openblas_get_num_threads"))


def _openblas_libraries() -> list[str]:
    """Paths of the OpenBLAS libraries loaded in this process (Linux; elsewhere none)."""
    try:
        with open("/proc/self/maps", encoding="utf-8") as fh:
            return sorted({line.split()[-1] for line in fh
                           if "openblas" in line.lower() and "/" in line})
    except OSError:
        return []


@contextlib.contextmanager
def one_blas_thread() -> Iterator[bool]:
    """Run the block with every loaded OpenBLAS on one thread, then restore the counts.

    As ``OPENBLAS_NUM_THREADS=1`` at start-up, but for a process whose numpy
    is already loaded (``import numpy`` reads the variable once).

    Yields:
        Whether numpy's OpenBLAS was found and set (False: the results may
        depend on the thread count, unless ``OPENBLAS_NUM_THREADS=1`` is set).
    """
    import numpy as _np  # noqa: F401 - loaded, so that its OpenBLAS is in the maps

    undo = []
    for path in _openblas_libraries():
        try:
            lib = ctypes.CDLL(path)
        except OSError:
            continue
        for setter, getter in _BLAS_THREADS:
            if hasattr(lib, setter) and hasattr(lib, getter):
                n = int(getattr(lib, getter)())
                getattr(lib, setter)(1)
                undo.append((getattr(lib, setter), n))
                break
    try:
        yield bool(undo)
    finally:
        for setter_fn, n in undo:
            setter_fn(n)


def init_layers(sizes: list[int], rng: np.random.Generator) -> Layers:
    """Glorot-uniform weights and zero biases.

    Args:
        sizes: ``[inputs, hidden..., outputs]``.
        rng: The only source of randomness.

    Returns:
        The layers, input first.
    """
    out = []
    for n_in, n_out in zip(sizes[:-1], sizes[1:], strict=True):
        lim = np.sqrt(6.0 / (n_in + n_out))
        out.append((rng.uniform(-lim, lim, (n_out, n_in)), np.zeros(n_out)))
    return out


def forward(layers: Layers, x: FloatArray) -> FloatArray:
    """Outputs ``(R, outputs)`` for inputs ``(R, inputs)`` (tanh hidden, linear last)."""
    y = x
    for i, (w, b) in enumerate(layers):
        y = y @ w.T + b
        if i < len(layers) - 1:
            y = np.tanh(y)
    return y


def _grads(layers: Layers, x: FloatArray, y: FloatArray) -> tuple[float, Layers]:
    """Mean squared error (mean over rows, sum over outputs) and its gradients."""
    acts = [x]
    for i, (w, b) in enumerate(layers):
        z = acts[-1] @ w.T + b
        acts.append(np.tanh(z) if i < len(layers) - 1 else z)
    err = acts[-1] - y
    loss = float(np.mean(np.sum(err * err, axis=1)))
    delta = 2.0 * err / len(x)
    grads: Layers = []
    for i in range(len(layers) - 1, -1, -1):
        w = layers[i][0]
        grads.append((delta.T @ acts[i], delta.sum(axis=0)))
        if i:
            delta = (delta @ w) * (1.0 - acts[i] * acts[i])
    return loss, grads[::-1]


@dataclass
class Adam:
    """Adam (Kingma and Ba) over a list of layers.

    Attributes:
        lr: Step size (in the units of the weights).
        beta1: First-moment decay.
        beta2: Second-moment decay.
        eps: Denominator floor.
    """

    lr: float = 1e-3
    beta1: float = 0.9
    beta2: float = 0.999
    eps: float = 1e-8

    def __post_init__(self) -> None:
        self.t = 0
        self.m: list[FloatArray] = []
        self.v: list[FloatArray] = []

    def step(self, params: list[FloatArray], grads: list[FloatArray]) -> None:
        """Update ``params`` in place from their ``grads``."""
        if not self.m:
            self.m = [np.zeros_like(p) for p in params]
            self.v = [np.zeros_like(p) for p in params]
        self.t += 1
        c1 = 1.0 - self.beta1 ** self.t
        c2 = 1.0 - self.beta2 ** self.t
        for p, g, m, v in zip(params, grads, self.m, self.v, strict=True):
            m *= self.beta1
            m += (1.0 - self.beta1) * g
            v *= self.beta2
            v += (1.0 - self.beta2) * g * g
            p -= self.lr * (m / c1) / (np.sqrt(v / c2) + self.eps)


def fit(layers: Layers, x: FloatArray, y: FloatArray, epochs: int, batch: int,
        opt: Adam, rng: np.random.Generator) -> list[float]:
    """Minibatch Adam on the mean squared error, in place.

    Args:
        layers: The network, updated in place.
        x: ``(R, inputs)`` inputs (already standardized).
        y: ``(R, outputs)`` targets.
        epochs: Passes over the data.
        batch: Rows per step.
        opt: The optimizer (keeps its moments between calls).
        rng: Shuffles the rows, one permutation per epoch.

    Returns:
        The mean training loss of each epoch.
    """
    flat = [a for wb in layers for a in wb]
    history = []
    for _ in range(epochs):
        order = rng.permutation(len(x))
        total = 0.0
        for start in range(0, len(x), batch):
            rows = order[start:start + batch]
            loss, grads = _grads(layers, x[rows], y[rows])
            opt.step(flat, [a for wb in grads for a in wb])
            total += loss * len(rows)
        history.append(total / len(x))
    return history
