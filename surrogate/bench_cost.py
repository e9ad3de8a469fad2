"""What a surrogate costs the predictor: one query's wall time at the batch sizes it asks for.

    python -m surrogate.bench_cost MODEL [MODEL ...] [--batches 1,2,7442] [--repeats 200]
        [--beside TEXT] [--out results/bench/surrogate_cost.json] [--json]

A single gesture's Newton steps query the joint model in batches of 1 or 2 (one per joint
state), a 61 x 61 atlas in batches of 7,442 (61² pressure pairs, two joints each). For each
model and batch size: the median wall time (ms) of one no-grad float64 call with the
anchors, the cap rotation and the Jacobian (``outputs(x, jacobian=True, cap=True)``, what
the predictor's Newton steps ask for), on one thread, inputs drawn in the model's input
box. The models are timed interleaved, call by call (A, B, A, B, ...), so that a noisy
machine slows them alike; the JSON gives each median, and each model's ratio to the
first model's at the same batch size (the same-run ratio). Units: ms, samples/s.
"""
from __future__ import annotations

import os
import sys
import time

import numpy as np
import torch

from contract import cli
from surrogate.artefacts import BENCH_COST
from surrogate.evaluate import input_box
from surrogate.model import load_surrogate

BATCHES = (1, 2, 7442)


def inputs(model, n: int, seed: int = 0) -> torch.Tensor:
    """n float64 inputs drawn uniformly in the model's input box."""
    box = torch.as_tensor(input_box(model), dtype=torch.float64)
    u = torch.rand(n, len(box), generator=torch.Generator().manual_seed(seed), dtype=torch.float64)
    return (2 * u - 1) * box


def interleaved(models: list, batch: int, repeats: int) -> list[float]:
    """Median ms of one call per model at ``batch``, the models called in turn."""
    xs = [inputs(m, batch) for m in models]
    times = [[] for _ in models]
    with torch.no_grad():
        for m, x in zip(models, xs):            # warm-up
            for _ in range(5):
                m.outputs(x, jacobian=True, cap=m.has_cap_rotation)
        for _ in range(repeats):
            for k, (m, x) in enumerate(zip(models, xs)):
                t0 = time.perf_counter()
                m.outputs(x, jacobian=True, cap=m.has_cap_rotation)
                times[k].append(time.perf_counter() - t0)
    return [1e3 * float(np.median(t)) for t in times]


def bench(paths: list[str], batches=BATCHES, repeats: int = 200) -> dict:
    """The benchmark's document (module docstring)."""
    torch.set_num_threads(1)
    models = [load_surrogate(p) for p in paths]
    rows = []
    for batch in batches:
        ms = interleaved(models, batch, repeats if batch < 1000 else max(10, repeats // 20))
        rows.append({"batch": batch, "models": [
            {"model": p, "ms": t, "samples_per_s": 1e3 * batch / t, "ratio_to_first": t / ms[0]}
            for p, t in zip(paths, ms)]})
    return {"models": [{"model": p, "hidden": list(m.config.hidden), "symmetric": m.config.symmetric,
                        "equivariant": m.config.equivariant} for p, m in zip(paths, models)],
            "threads": 1, "dtype": "float64", "outputs": "anchors, cap rotation, Jacobian",
            "repeats": repeats, "cases": rows, "load_average": os.getloadavg()[0]}


def main(argv=None) -> int:
    ap = cli.Parser(prog="python -m surrogate.bench_cost", description=__doc__.split("\n\n")[0])
    ap.add_argument("models", nargs="+", help="surrogate checkpoints (.pt); ratios are to the first")
    ap.add_argument("--batches", type=cli.number_list(1, 1e6), default=BATCHES,
                    help="batch sizes (default 1,2,7442)")
    ap.add_argument("--repeats", type=cli.number(1, None, integer=True), default=200,
                    help="calls per model and batch size below 1,000 (a twentieth above)")
    ap.add_argument("--beside", default="", help="what else ran on the machine (recorded)")
    ap.add_output("--out", suffix=".json", help="write the figures (JSON, atomic)")
    args = ap.parse_args(argv)
    with ap.errors():
        doc = bench(args.models, [int(b) for b in args.batches], args.repeats) | {"beside": args.beside}
        if args.out:
            BENCH_COST.write(args.out, doc)
    if args.json:
        cli.print_json(doc)
    else:
        for row in doc["cases"]:
            print(f"batch {row['batch']}: " + "; ".join(
                f"{m['model']} {m['ms']:.3f} ms (x{m['ratio_to_first']:.2f})" for m in row["models"]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
