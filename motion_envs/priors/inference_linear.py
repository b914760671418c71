"""Linear layers at inference through oneDNN on the CPU: the matmul, its bias and its activation in one call.

Why (measured, torch 2.13.0's CPU wheel, 2 cores): torch's fp32 `F.linear` calls MKL, whose sgemm runs AVX2 code
on AMD CPUs even where they have AVX-512 (EPYC Zen 4: 180 GFLOP/s on the priors' layer shapes, oneDNN 410-425);
oneDNN picks its kernels by the CPU's instruction set alone. With oneDNN held to AVX2 (`ONEDNN_MAX_CPU_ISA=AVX2`,
an AVX2-only CPU's kernels) it is still 10% ahead of MKL. oneDNN also applies the bias and the activation inside
the matmul, which saves two passes over every layer's output (the GAMMA regressor's residual blocks at 8,192 rows:
3.4 -> 2.0 ms fp32); in bf16 those passes cost as much as the matmuls they follow.

Where: CPU tensors without autograd (the op has no backward: training keeps `nn.Linear`), fp32, or bf16 where
the CPU multiplies bf16 natively (oneDNN emulates it elsewhere, 7x slower than fp32). Elsewhere, and on CUDA,
the plain modules run. The sums are ordered differently from MKL's: outputs agree to ~1e-5 relative in fp32
(tested); on one machine a given shape always takes the same kernel, so runs stay bit-for-bit reproducible.
"""

from __future__ import annotations

from collections.abc import Iterable

import torch
from torch import nn
from torch.nn import functional as F

from motion_envs.precision import native_bf16

ONEDNN_LINEAR = getattr(torch.ops.mkldnn, "_linear_pointwise", None) if torch.backends.mkldnn.is_available() else None
"""oneDNN's linear with a fused activation, or (`.binary`) a fused sum (what torch.compile's CPU backend calls), where
this torch has it."""

ONEDNN_BF16 = ONEDNN_LINEAR is not None and bool(torch.ops.mkldnn._is_mkldnn_bf16_supported())
"""Whether oneDNN has bf16 kernels on this CPU (it needs AVX-512 at least): asked of torch, not of the CPU flags, so
that a wrong or mocked flag list (`motion_envs.precision.cpu_flags`) never sends bf16 to a primitive oneDNN cannot
build (on an AVX2-only CPU: "could not create a primitive descriptor for the inner product")."""

ACTIVATIONS: dict[type[nn.Module], str] = {nn.ReLU: "relu", nn.Tanh: "tanh", nn.LeakyReLU: "leaky_relu"}
"""Activation modules oneDNN applies inside the matmul, by its names for them."""


def takes_onednn(x: torch.Tensor) -> bool:
    """Whether linears on `x` run through oneDNN (see the module doc)."""
    if ONEDNN_LINEAR is None or x.device.type != "cpu" or torch.is_grad_enabled():
        return False
    return x.dtype == torch.float32 or (x.dtype == torch.bfloat16 and ONEDNN_BF16 and native_bf16())


def linear(x: torch.Tensor, weight: torch.Tensor, bias: torch.Tensor | None = None,
           activation: nn.Module | None = None, add: torch.Tensor | None = None) -> torch.Tensor:  # fmt: skip
    """activation(x @ weight.T + bias), or x @ weight.T + bias + `add`, for x (..., in), weight (out, in), bias (out,)
    or None, `add` (..., out) or None (a residual or a precomputed share of the sum; not with `activation`);
    `activation` one of `ACTIVATIONS`' modules or None. One oneDNN call where `takes_onednn(x)` (the sum as its
    binary post-op: at 8,192 x 128 in bf16, 2 cores, 279 us against 348 for the linear and a separate add); a strided
    weight (a slice of columns) is copied first: oneDNN's kernel for it is a reference loop (1,024 × 201 -> 768:
    1.9 s against 1 ms). Returns a fresh tensor."""
    if activation is not None and add is not None:
        raise ValueError("linear applies an activation or adds a tensor, not both")
    if not takes_onednn(x):
        y = F.linear(x, weight, bias)
        if add is not None:
            return y + add if torch.is_grad_enabled() else y.add_(add)
        return y if activation is None else activation(y)
    x, weight = x.contiguous(), weight.contiguous()
    if add is not None:
        return ONEDNN_LINEAR.binary(x, add.contiguous(), weight, bias, "add")
    if activation is None:
        return ONEDNN_LINEAR(x, weight, bias, "none", [], "")
    scalars = [activation.negative_slope] if isinstance(activation, nn.LeakyReLU) else []
    return ONEDNN_LINEAR(x, weight, bias, ACTIVATIONS[type(activation)], scalars, "")


def run_layers(layers: Iterable[nn.Module], x: torch.Tensor) -> torch.Tensor:
    """`nn.Sequential`'s forward over `layers`, each `nn.Linear` and the activation right after it as one `linear`
    call; other modules run as themselves."""
    layers = list(layers)
    index = 0
    while index < len(layers):
        layer = layers[index]
        if isinstance(layer, nn.Linear):
            following = layers[index + 1] if index + 1 < len(layers) else None
            activation = following if type(following) in ACTIVATIONS else None
            x = linear(x, layer.weight, layer.bias, activation)
            index += 2 if activation is not None else 1
        else:
            x = layer(x)
            index += 1
    return x


class InferenceSequential(nn.Sequential):
    """`nn.Sequential` whose no-grad CPU forward fuses each linear with its activation (`run_layers`); the same
    parameters and state-dict keys as `nn.Sequential`."""

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return run_layers(self, x) if takes_onednn(x) else super().forward(x)
