"""Inference fast path for SGCN's stacks of asymmetric convolutions over few-channel interaction maps.

Each ``AsymmetricConv`` is ``PReLU(conv (3x1) + conv (1x3) + bias) + x``: a cross-shaped 3x3 convolution,
i.e. five taps (up, down, left, right, centre), each a C x C channel matrix. For C = 4 channels oneDNN's
convolution spends most of its time on overhead, so without gradients ``CrossStack`` runs a whole stack as

    Z = taps (5C, C + 1) @ X (C + 1, L)        one small matmul per layer (the last row of X is ones: bias)
    Y = Z_centre + shifted Z_up, Z_down, Z_left, Z_right
    X' = (PReLU(Y) + X) * mask

over a flat, zero-padded layout: every map is stored as (H + 2) x (W + 2) with a zero border, maps follow
each other, and the C channels are the rows of X. A spatial shift by one row or column is then a shift of
the flattened array by W + 2 or 1, so every shifted term is one contiguous slice. Border positions pick up
values during a layer and are zeroed again by the mask (the interior indicator times the caller's mask).
All intermediates live in buffers reused across calls. Equal to the layers' own forward up to float
rounding (``tests/predictor/test_cross_conv.py``).
"""

from __future__ import annotations

import threading
from collections.abc import Sequence

import torch
from torch import Tensor, nn
from torch.nn import functional as F

WORKSPACES = 4  # buffer sets kept per thread and stack


def pack_layer(layer: nn.Module) -> tuple[Tensor, float]:
    """Taps (5C, C + 1) of one ``AsymmetricConv`` (row blocks up, down, left, right, centre; the centre
    block's last column is the bias) and its PReLU slope."""
    with torch.no_grad():
        wh, ww = layer.conv_h.weight[..., 0], layer.conv_w.weight[:, :, 0]  # (C, C, 3) each
        c = wh.shape[0]
        taps = torch.zeros(5 * c, c + 1, dtype=wh.dtype, device=wh.device)
        taps[:, :c] = torch.cat([wh[..., 0], wh[..., 2], ww[..., 0], ww[..., 2], wh[..., 1] + ww[..., 1]])
        taps[4 * c :, c] = layer.conv_w.bias
        return taps, float(layer.act.weight)


def _workspace_key(x: Tensor) -> tuple:
    """What a workspace depends on; buffers made in inference mode cannot be written outside it."""
    return x.shape, x.dtype, x.device, torch.is_inference_mode_enabled()


class _Workspace:
    """Buffers for one input shape (C, *batch, H, W) and every view the layers use, made once: borders and
    the bias row are set here and stay."""

    def __init__(self, x: Tensor) -> None:
        c, batch, (h, w) = x.shape[0], x.shape[1:-2], x.shape[-2:]
        zeros = lambda *shape: torch.zeros(*shape, dtype=x.dtype, device=x.device)  # noqa: E731
        maps = [zeros(c + 1, *batch, h + 2, w + 2) for _ in range(2)]  # (C + 1, *batch, H + 2, W + 2)
        for m in maps:
            m[c] = 1.0  # the bias row
        keep = zeros(c, *batch, h + 2, w + 2)  # the mask per channel, zero on the borders
        r, n = w + 2, keep.numel()  # flat offset of one row; flat length of the C channel rows
        core = slice(r, n - r)  # the flat positions a layer writes
        self.maps = maps
        self.mats = [m.view(c + 1, -1) for m in maps]  # matmul operands (C + 1, L)
        self.cores = [m.view(-1)[core] for m in maps]
        self.inner = maps[0][:c, ..., 1:-1, 1:-1]  # where the input goes
        self.keep_inner, self.keep = keep[..., 1:-1, 1:-1], keep.view(-1)[core]
        self.z = zeros(5 * c, n // c)  # (5C, L): every tap applied at every position
        z = self.z.view(5, -1)  # tap blocks, each the C channel rows flattened
        # centre, up (the row above: offset -r), down (+r), left (-1), right (+1)
        self.terms = [z[4, core], z[0, : n - 2 * r], z[1, 2 * r :], z[2, r - 1 : n - r - 1], z[3, r + 1 : n - r + 1]]
        self.full = zeros(n)  # the gate of the output, borders included
        self.y = self.full[core]  # the layer sums
        self.gated = self.full.view(c, *batch, h + 2, w + 2)[..., 1:-1, 1:-1].movedim(0, -3)


class CrossStack:
    """Runs a stack of ``AsymmetricConv`` layers without gradients on ``x * mask``: ``x = layer(x) * mask``
    per layer.

    The packed weights are cached and rebuilt when a parameter of the stack was replaced, moved (``.data``,
    ``.to``) or changed in place (``load_state_dict``, optimiser steps), which the parameters' identity,
    storage and version counters reveal. Buffers are per thread and input shape.
    """

    def __init__(self, layers: Sequence[nn.Module]) -> None:
        self.layers = layers
        self._reset()

    def _reset(self) -> None:
        self._cache: tuple[list[tuple[dict, str]], list[Tensor], list, list[Tensor], list[float]] | None = None
        self._local = threading.local()

    def __getstate__(self) -> dict:  # caches and thread-local buffers are not copied or pickled
        return {"layers": self.layers}

    def __setstate__(self, state: dict) -> None:
        self.layers = state["layers"]
        self._reset()

    @staticmethod
    def _state(slots: list[tuple[dict, str]]) -> list[tuple[int, int, int]]:
        return [(id(p), p.data_ptr(), p._version) for p in (d[name] for d, name in slots)]

    def packed(self) -> tuple[list[Tensor], list[float]]:
        """Taps (5C, C + 1) and PReLU slope of each layer, for the stack's current weights."""
        cache = self._cache
        if cache is not None and self._state(cache[0]) == cache[2]:
            return cache[3], cache[4]
        slots = [(m._parameters, name) for layer in self.layers for m in layer.modules()
                 for name, p in m._parameters.items() if p is not None]
        packed = [pack_layer(layer) for layer in self.layers]
        taps, slopes = [t for t, _ in packed], [a for _, a in packed]
        # the parameters are held so that their ids stay unique while cached
        self._cache = (slots, [d[name] for d, name in slots], self._state(slots), taps, slopes)
        return taps, slopes

    def _workspace(self, x: Tensor) -> _Workspace:
        """This thread's buffers for ``x``: the last ``WORKSPACES`` shapes are kept (pedestrian counts vary)."""
        spaces: dict | None = getattr(self._local, "spaces", None)
        if spaces is None:
            spaces = self._local.spaces = {}
        key = _workspace_key(x)
        ws = spaces.get(key)
        if ws is None:
            if len(spaces) >= WORKSPACES:
                del spaces[next(iter(spaces))]  # the oldest
            ws = spaces[key] = _Workspace(x)
        return ws

    def __call__(self, x: Tensor, mask: Tensor | None = None, gate: float | None = None) -> Tensor:
        """Apply the stack.

        Args:
            x: (C, *batch, H, W) maps, channels first (any strides).
            mask: multiplier of the input and after every layer, the same for all channels, broadcastable
                to (*batch, H, W); None for none.
            gate: if given, return ``threshold(sigmoid(out), gate, 0)`` (SGCN's interaction masks).
        Returns:
            Without ``gate``: the output (C, *batch, H, W), a strided view into a buffer that this thread's
            next call overwrites. With ``gate``: a new contiguous tensor (*batch, C, H, W).
        """
        taps, slopes = self.packed()
        ws = self._workspace(x)
        if mask is None:
            ws.inner.copy_(x)
            ws.keep_inner.fill_(1.0)
        else:
            torch.mul(x, mask, out=ws.inner)
            ws.keep_inner.copy_(mask)  # broadcast over the channels
        y, keep, (centre, up, down, left, right) = ws.y, ws.keep, ws.terms
        for k, (t, slope) in enumerate(zip(taps, slopes, strict=True)):
            torch.mm(t, ws.mats[k % 2], out=ws.z)
            torch.add(centre, up, out=y)
            y += down
            y += left
            y += right
            F.leaky_relu(y, slope, inplace=True)  # PReLU with one slope
            y += ws.cores[k % 2]
            torch.mul(y, keep, out=ws.cores[(k + 1) % 2])
        out = ws.maps[len(slopes) % 2][: x.shape[0]]
        if gate is None:
            return out[..., 1:-1, 1:-1]
        torch.sigmoid(out.view(-1), out=ws.full)  # contiguous (fast), borders included
        out = torch.empty(ws.gated.shape, dtype=x.dtype, device=x.device)
        return torch.threshold(ws.gated, gate, 0.0, out=out)
