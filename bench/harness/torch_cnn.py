"""PyTorch's side of bench/cnn: the image encoders' forward and forward-plus-backward
milliseconds per batch, at the shapes `fairgrasp bench cnn` measures (NCHW float input, the
layout PyTorch's convolutions want), on the threads given. One JSON object per line."""

from __future__ import annotations

import argparse
import json
import time

import torch

SHAPES = [
    # name, (filters, kernel, stride) per convolution, image side, features
    ("nature_cnn_84", [(32, 8, 4), (64, 4, 2), (64, 3, 1)], 84, 512),
    ("fast_cnn_64", [(16, 5, 2), (32, 3, 2), (32, 3, 2)], 64, 64),
]


def encoder(layers, side, features):
    modules, channels = [], 3
    for filters, kernel, stride in layers:
        modules += [torch.nn.Conv2d(channels, filters, kernel, stride), torch.nn.ReLU()]
        channels = filters
    convs = torch.nn.Sequential(*modules, torch.nn.Flatten())
    with torch.no_grad():
        flat = convs(torch.zeros(1, 3, side, side)).shape[1]
    return torch.nn.Sequential(convs, torch.nn.Linear(flat, features), torch.nn.ReLU())


def timed(seconds, f):
    f()
    start, calls = time.perf_counter(), 0
    while calls == 0 or time.perf_counter() - start < seconds:
        f()
        calls += 1
    return (time.perf_counter() - start) / calls


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--batch", type=int, default=64)
    parser.add_argument("--seconds", type=float, default=3.0)
    parser.add_argument("--threads", type=int, default=1)
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    torch.manual_seed(0)
    for name, layers, side, features in SHAPES:
        net = encoder(layers, side, features)
        x = torch.rand(args.batch, 3, side, side)

        def forward():
            with torch.no_grad():
                net(x)

        def step():
            net.zero_grad(set_to_none=True)
            net(x).sum().backward()

        print(json.dumps({
            "shape": name, "batch": args.batch, "threads": args.threads,
            "torch": torch.__version__,
            "torch_forward_ms": timed(args.seconds, forward) * 1e3,
            "torch_step_ms": timed(args.seconds, step) * 1e3,
        }))


if __name__ == "__main__":
    main()
