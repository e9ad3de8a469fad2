"""Joint anchors for given loads, from the command line.

    python -m surrogate.predict --model results/surrogate/improved.pt \\
        --p 0.1 --f1 1 --f2 0 --m 10 [--allow-extrapolation] [--json]

prints the anchors r_1..r_k (mm, joint frame, relative to the proximal centre; k the
model's joint's anchor count), phi_end = atan2(y_k - y_k-1, x_k - x_k-1) (rad and deg) and,
for a model with the cap-rotation head, the distal cap's rotation (rad and deg; null
otherwise). A value that is not a finite number is always refused, before the model is
loaded; inputs outside the model's training box (its joint's [input_box]; the paper's
|P| <= 0.3 MPa, |F1|, |F2| <= 3 N, |M| <= 100 N·mm, contract.spec) are refused unless
--allow-extrapolation is given, which the output records ("extrapolation": true). Either
refusal is one line, exit 2.
JSON keys: model, inputs {P_MPa, F1_N, F2_N, M_Nmm}, extrapolation, anchors_mm (k x 2),
phi_end_rad, phi_end_deg, cap_rotation_rad, cap_rotation_deg.

The batched, differentiable torch API is ``surrogate.load_surrogate(path)`` (a frozen
float64 module, (..., 4) -> (..., k, 2) mm; ``with_cap`` adds the cap rotation), with
``surrogate.check_box(x)`` for the box check and ``surrogate.phi_end(anchors)``.
"""

from __future__ import annotations

import math
import sys

import torch

from contract import cli
from contract.spec import INPUT_NAMES, INPUT_UNITS, check_box, phi_end
from surrogate.model import load_surrogate

HELP = {"p": "pressure P (MPa, signed)", "f1": "axial end force F1 (N)",
        "f2": "transverse end force F2 (N)", "m": "end moment M (N*mm, CCW positive)"}


def main(argv=None) -> int:
    ap = cli.Parser(prog="python -m surrogate.predict",
                    description="Predict the joint's anchor points and phi_end.")
    ap.add_argument("--model", default="results/surrogate/improved.pt", help="checkpoint (.pt)")
    for name, unit in zip(INPUT_NAMES, INPUT_UNITS):
        ap.add_argument(f"--{name.lower()}", type=cli.number(unit=unit), required=True,
                        help=HELP[name.lower()])
    ap.add_argument("--allow-extrapolation", action="store_true",
                    help="accept inputs outside the training box (flagged in the output)")
    args = ap.parse_args(argv)
    torch.set_num_threads(1)
    x = [args.p, args.f1, args.f2, args.m]
    with ap.errors():
        check_box([x], allow_extrapolation=True)      # not finite: refused before loading
        model = load_surrogate(args.model)
        outside = check_box([x], args.allow_extrapolation, box=model.input_box)
    with torch.no_grad():
        if model.has_cap_rotation:
            anchors, cap = model.with_cap(torch.tensor(x, dtype=torch.float64))
            cap = cap.item()
        else:
            anchors, cap = model(torch.tensor(x, dtype=torch.float64)), None
    phi = phi_end(anchors).item()
    out = {"model": args.model,
           "inputs": {"P_MPa": args.p, "F1_N": args.f1, "F2_N": args.f2, "M_Nmm": args.m},
           "extrapolation": outside > 0,
           "anchors_mm": anchors.tolist(),
           "phi_end_rad": phi,
           "phi_end_deg": math.degrees(phi),
           "cap_rotation_rad": cap,
           "cap_rotation_deg": None if cap is None else math.degrees(cap)}
    if args.json:
        cli.print_json(out)
    else:
        print(f"inputs P={args.p} MPa F1={args.f1} N F2={args.f2} N M={args.m} N*mm"
              + ("  (EXTRAPOLATION)" if outside else ""))
        for i, (ax, ay) in enumerate(out["anchors_mm"], 1):
            print(f"  r_{i:<2d} x {ax:9.4f} mm  y {ay:9.4f} mm")
        print(f"  phi_end {phi:.6f} rad = {math.degrees(phi):.4f} deg")
        if cap is not None:
            print(f"  cap rotation {cap:.6f} rad = {math.degrees(cap):.4f} deg")
    return 0


if __name__ == "__main__":
    sys.exit(main())
