"""The smallest case of the bfloat16 Conv3d fault behind train/precision.py's check.

One weight gradient of the 3D CNN's shape layer (Conv3d 1 -> 32, kernel
(5, 5, 16), stride (2, 2, 4), padding (2, 2, 8)) over a batch of 3 x 3 zones,
computed in bfloat16 and in float32, compared per kernel depth tap. On oneDNN
3.12 with a bfloat16 kernel (`jit_bf16:avx512_core_bf16`; AVX-512 BF16 or
AMX CPUs, or AVX-512 CPUs emulating it) the first three depth taps are wrong
(inf, or errors of order 1 and far more; which, can change from one process
to the next); with `--zones 8` (the kernel fits the input) or
under `ONEDNN_MAX_CPU_ISA=AVX2` (no bfloat16 kernel) every tap agrees.

    python scripts/repro_bf16_conv3d.py [--zones 3] [--threads 1] [--repeats 3]
    ONEDNN_VERBOSE=1 python scripts/repro_bf16_conv3d.py --repeats 1   # the primitive's name and problem

Runs in about a second. Prints, per repeat, each depth tap's relative error
||g_bf16 - g_f32|| / ||g_f32|| (bfloat16's rounding gives ~0.003-0.02).

Cited by docs/deviations.md, "Training protocol" (the 3D CNN's shape model at
3x3 trains in float32).
"""

from __future__ import annotations

import argparse

import torch

KERNEL, STRIDE, PADDING, CHANNELS, BINS, BATCH = (5, 5, 16), (2, 2, 4), (2, 2, 8), 32, 77, 256


def weight_gradient(x: torch.Tensor, w: torch.Tensor, grad_out: torch.Tensor) -> torch.Tensor:
    """dL/dw (CHANNELS, 1, *KERNEL) float32 of conv3d(x, w) given dL/d(output), in x's dtype."""
    mask = (False, True, False)  # the weight's gradient only, as when the input needs none (the network's first layer)
    g = torch.ops.aten.convolution_backward(grad_out, x, w, None, STRIDE, PADDING, (1, 1, 1), False, (0, 0, 0), 1, mask)[1]
    return g.float()


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--zones", type=int, default=3, help="zones per side of the input (3: the fault; 8: the kernel fits)")
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--repeats", type=int, default=3)
    args = p.parse_args()
    torch.set_num_threads(args.threads)
    gen = torch.Generator().manual_seed(0)
    x = torch.randn(BATCH, 1, args.zones, args.zones, BINS, generator=gen)
    w = torch.randn(CHANNELS, 1, *KERNEL, generator=gen) * 0.05
    out_shape = torch.nn.functional.conv3d(x, w, None, STRIDE, PADDING).shape
    grad_out = torch.randn(out_shape, generator=gen)
    ref = weight_gradient(x, w, grad_out)
    print(f"torch {torch.__version__}, {args.zones}x{args.zones} zones, {args.threads} thread(s)")
    for r in range(args.repeats):
        g = weight_gradient(x.bfloat16(), w.bfloat16(), grad_out.bfloat16())
        errors = [float((g[:, :, d] - ref[:, :, d]).norm() / ref[:, :, d].norm()) for d in range(KERNEL[0])]
        print(f"repeat {r + 1}: relative error per depth tap " + "  ".join(f"{e:.3g}" for e in errors))


if __name__ == "__main__":
    main()
