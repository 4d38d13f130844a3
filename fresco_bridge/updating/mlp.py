"""A small fully connected tanh network with a flat parameter vector and an analytic Jacobian.

The paper's network is 6 -> 10 -> 10 -> 10 -> 1: "tansig" hidden layers, a "purelin" output,
301 weights and biases. Levenberg-Marquardt needs the Jacobian of the output with respect to
every parameter for every sample; for a scalar output that is one backward sweep over the
batch (``delta_l = (delta_{l+1} @ W_{l+1}) * (1 - a_l**2)``), no autograd needed.

Flat layout of ``theta``: for each layer in order, ``W`` (out x in, row-major) then ``b`` (out),
the same order as a torch ``nn.Sequential`` state dict (``0.weight``, ``0.bias``, ``2.weight``…).
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from .base import UpdaterError

FloatArray = npt.NDArray[np.float64]

__all__ = ["PAPER_LAYERS", "Mlp"]

PAPER_LAYERS = (6, 10, 10, 10, 1)
"""The paper's architecture (Fig. 8): 6 inputs, 3 hidden layers of 10, 1 output; 301 parameters."""


@dataclass(frozen=True, slots=True)
class _Slot:
    w: slice
    b: slice
    shape: tuple[int, int]


class Mlp:
    """Shape of a tanh MLP with a linear scalar output; parameters live in a flat vector."""

    __slots__ = ("_slots", "layers", "n_params")

    def __init__(self, layers: Sequence[int] = PAPER_LAYERS) -> None:
        sizes = tuple(int(n) for n in layers)
        if len(sizes) < 2 or any(n < 1 for n in sizes) or sizes[-1] != 1:
            raise UpdaterError(
                f"network layers must be >= 2 positive sizes ending in 1 output, got {list(layers)}"
            )
        self.layers = sizes
        slots = []
        offset = 0
        for n_in, n_out in itertools.pairwise(sizes):
            w = slice(offset, offset + n_in * n_out)
            offset += n_in * n_out
            b = slice(offset, offset + n_out)
            offset += n_out
            slots.append(_Slot(w, b, (n_out, n_in)))
        self._slots = tuple(slots)
        self.n_params = offset

    def __repr__(self) -> str:
        return f"Mlp({list(self.layers)}, {self.n_params} parameters)"

    def unpack(self, theta: FloatArray) -> list[tuple[FloatArray, FloatArray]]:
        """(W, b) views per layer into ``theta`` (no copies)."""
        if theta.shape != (self.n_params,):
            raise UpdaterError(f"{self!r}: theta must have shape ({self.n_params},), "
                               f"got {theta.shape}")
        return [(theta[s.w].reshape(s.shape), theta[s.b]) for s in self._slots]

    def init_params(self, rng: np.random.Generator) -> FloatArray:
        """Nguyen-Widrow start (MATLAB's ``initnw``, the default of ``feedforwardnet``).

        Each hidden layer's weight rows get norm ``0.7 * S**(1/R)`` (S neurons, R inputs) and
        biases spread over ``[-norm, norm]``, so the tanh units cover the [0, 1] inputs;
        the linear output layer starts uniform in [-0.5, 0.5].
        """
        theta = np.empty(self.n_params)
        last = len(self._slots) - 1
        for i, s in enumerate(self._slots):
            n_out, n_in = s.shape
            if i == last:
                theta[s.w] = rng.uniform(-0.5, 0.5, n_out * n_in)
                theta[s.b] = rng.uniform(-0.5, 0.5, n_out)
                continue
            beta = 0.7 * n_out ** (1.0 / n_in)
            w = rng.uniform(-1.0, 1.0, (n_out, n_in))
            w *= beta / np.linalg.norm(w, axis=1, keepdims=True)
            theta[s.w] = w.ravel()
            theta[s.b] = beta * np.linspace(-1.0, 1.0, n_out) * rng.choice((-1.0, 1.0), n_out)
        return theta

    def forward(self, theta: FloatArray, x: FloatArray) -> FloatArray:
        """Outputs (n,) for inputs x (n x inputs)."""
        return self.activations(theta, x)[-1][:, 0]

    def activations(self, theta: FloatArray, x: FloatArray) -> list[FloatArray]:
        """[x, hidden activations…, output (n x 1)]: a forward pass kept for ``jacobian``."""
        params = self.unpack(theta)
        acts = [x]
        a = x
        for w, b in params[:-1]:
            a = np.tanh(a @ w.T + b)
            acts.append(a)
        w, b = params[-1]
        acts.append(a @ w.T + b)
        return acts

    def jacobian(self, theta: FloatArray, x: FloatArray,
                 out: npt.NDArray[np.floating[Any]] | None = None,
                 acts: list[FloatArray] | None = None,
                 row_scale: FloatArray | None = None,
                 ) -> tuple[FloatArray, npt.NDArray[np.floating[Any]]]:
        """(outputs (n,), J (n x n_params)) with J[i, k] = d out_i / d theta_k.

        J is Fortran-ordered (``J.T`` is C-ordered): every block of ``J.T`` (a layer's weights
        or biases) is then written along contiguous samples, ~0.55x the time of a C-ordered J,
        and BLAS ``syrk``/``gemv`` read either order in place.
        ``acts`` (from :meth:`activations` at the same theta and x) saves the forward pass.
        ``out``: a Fortran-ordered (n, n_params) array to fill, float64 or float32 (computed
        in float64, stored in single precision).
        ``row_scale`` (n,) multiplies row i of J by ``row_scale[i]`` (LM's sqrt of the weights)
        at no extra cost: every block of J is linear in the output's seed delta.
        """
        params = self.unpack(theta)
        if acts is None:
            acts = self.activations(theta, x)
        n = x.shape[0]
        jac = np.empty((n, self.n_params), order="F") if out is None else out
        if jac.shape != (n, self.n_params) or not jac.flags.f_contiguous:
            raise UpdaterError(f"{self!r}: out must be a Fortran-ordered ({n}, {self.n_params}) "
                               f"array")
        jac_t = jac.T  # (n_params, n), C-ordered
        if row_scale is None:
            delta = np.ones((1, n))
        elif row_scale.shape == (n,):
            delta = row_scale[None, :].copy()
        else:
            raise UpdaterError(f"{self!r}: row_scale must have shape ({n},), got {row_scale.shape}")
        for layer in range(len(params) - 1, -1, -1):
            s = self._slots[layer]
            a_prev_t = acts[layer].T
            n_out, n_in = s.shape
            # A row block of the C-ordered J^T reshapes to (out, in, n) as a view: no copy.
            np.multiply(delta[:, None, :], a_prev_t[None, :, :],
                        out=jac_t[s.w].reshape(n_out, n_in, n))
            jac_t[s.b] = delta
            if layer:
                delta = (params[layer][0].T @ delta) * (1.0 - a_prev_t * a_prev_t)
        return acts[-1][:, 0], jac

    def input_gradient(self, theta: FloatArray, x_row: FloatArray) -> tuple[float, FloatArray]:
        """(output, d output / d input) for one input row (for the twin's tangent)."""
        params = self.unpack(theta)
        acts = []
        a = x_row
        for w, b in params[:-1]:
            a = np.tanh(w @ a + b)
            acts.append(a)
        w_last, b_last = params[-1]
        y = float(w_last[0] @ a + b_last[0])
        grad = w_last[0].copy()
        for layer in range(len(params) - 2, -1, -1):
            grad = (grad * (1.0 - acts[layer] * acts[layer])) @ params[layer][0]
        return y, grad
