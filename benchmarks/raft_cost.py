"""What a RAFT-small-class flow network costs on this machine's CPU: a training step and a flow.

    .venv/bin/python -m benchmarks.raft_cost [--threads 2] [--steps 4] [--write]

The network is cablesim's RAFT-style back end (:mod:`cablesim.perception.raft`, RAFT-small's
design: 1/8-resolution encoders, an all-pairs correlation pyramid, a convolutional GRU, 12
iterations), randomly initialised: the cost does not depend on the weights.  A training step is
a forward pass over a batch of 8 random 192x256 pairs, an L1 loss on the final flow, the backward
pass and an AdamW update on ``--threads`` torch threads (the median of ``--steps`` after one
warm-up); a flow is one 552x408 pair on one thread (the learned flow's speed aim is 60 ms).
Nothing is downloaded.  Writes ``benchmarks/results/raft_cost.md`` with ``--write``.
"""

from __future__ import annotations

import argparse
import statistics
import time

from benchmarks import RESULTS, write_results
from cablesim import provenance as pv
from cablesim.perception.raft import RaftConfig, build_raft
from cablesim.perception.torchfile import import_torch

BATCH, TRAIN_SIZE, FLOW_SIZE = 8, (192, 256), (408, 552)


def measure(threads: int, steps: int) -> dict[str, float]:
    torch = import_torch("the RAFT cost benchmark")
    torch.manual_seed(0)
    old = torch.get_num_threads()
    model = build_raft(RaftConfig())
    params = sum(p.numel() for p in model.parameters())
    opt = torch.optim.AdamW(model.parameters(), lr=1e-4)
    g = torch.Generator().manual_seed(0)
    x1 = torch.rand(BATCH, 3, *TRAIN_SIZE, generator=g) * 255
    x2 = torch.rand(BATCH, 3, *TRAIN_SIZE, generator=g) * 255
    target = torch.randn(BATCH, 2, *TRAIN_SIZE, generator=g)
    try:
        torch.set_num_threads(threads)
        model.train()
        times = []
        for _ in range(steps + 1):
            t0 = time.perf_counter()
            loss = (model(x1, x2) - target).abs().mean()
            opt.zero_grad(set_to_none=True)
            loss.backward()
            opt.step()
            times.append(time.perf_counter() - t0)
        torch.set_num_threads(1)
        model.eval()
        a = torch.rand(1, 3, *FLOW_SIZE, generator=g) * 255
        b = torch.rand(1, 3, *FLOW_SIZE, generator=g) * 255
        flows = []
        with torch.inference_mode():
            for _ in range(3):
                t0 = time.perf_counter()
                model(a, b)
                flows.append(time.perf_counter() - t0)
    finally:
        torch.set_num_threads(old)
    return {
        "params": float(params),
        "step_s": statistics.median(times[1:]),
        "flow_s": statistics.median(flows[1:]),
    }


def report(r: dict[str, float], threads: int, steps: int) -> str:
    return "\n".join(
        [
            "# A RAFT-small-class network on this CPU (`python -m benchmarks.raft_cost`)",
            "",
            f"- date: {pv.utc_date()}; commit {pv.git_commit()}; machine: {pv.machine()}",
            f"- `cablesim.perception.raft`, RaftConfig() defaults: {r['params'] / 1e6:.2f} M "
            "parameters, 12 iterations, randomly initialised",
            "",
            "| what | time |",
            "|---|---|",
            f"| one training step: {BATCH} pairs of {TRAIN_SIZE[1]}x{TRAIN_SIZE[0]}, forward, "
            f"backward, AdamW, {threads} threads (median of {steps}) | {r['step_s']:.2f} s |",
            f"| 100 000 such steps (the order of published RAFT schedules) | "
            f"{r['step_s'] * 1e5 / 3600:.0f} h |",
            f"| one flow at {FLOW_SIZE[1]}x{FLOW_SIZE[0]}, one thread (median of 2) | "
            f"{1000 * r['flow_s']:.0f} ms (aim: 60 ms) |",
            "",
        ]
    )


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--threads", type=int, default=2, help="torch threads for training")
    ap.add_argument("--steps", type=int, default=4, help="timed training steps")
    ap.add_argument("--write", action="store_true", help="write results/raft_cost.md")
    args = ap.parse_args(argv)
    if args.threads < 1 or args.steps < 1:
        ap.error("--threads and --steps must be at least 1")
    text = report(measure(args.threads, args.steps), args.threads, args.steps)
    if args.write:
        write_results(RESULTS / "raft_cost.md", text)
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
