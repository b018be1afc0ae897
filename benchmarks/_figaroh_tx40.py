"""FIGAROH's TX40 example identified on the training rows, its torque predicted on every row.

Run with a Python that has ``figaroh`` installed (``real_robots_benchmark.py --figaroh-python``), not
with dynid's: it imports nothing of dynid.  Arguments: the example's folder (figaroh-examples'
``examples/staubli_tx40``, laid out as that repository lays it out), the ``.npz`` to write, and
``--train-end`` (rows ``[0, train_end)`` of the example's recording are identified).

As the example's ``identification.py`` runs it (its configuration, its WLS refinement, its decimation by
10), from ``TX40Identification.initialize(truncate=(0, train_end))``.  The prediction processes the
whole recording FIGAROH's way (its filters, its differentiation, its border trimming) and multiplies
its base regressor by the identified base parameters, exactly as its validation metrics do.  With
``--coupled`` the example's own coupling hook (``add_additional_parameters``: motor 6's inertia,
viscous and Coulomb friction on joints 5 and 6) is called before solving, as the example did before
FIGAROH 1.0.2 stopped calling it, and its three columns are added when predicting; FIGAROH 1.0.2's
validation metrics rebuild the regressor without them and fail, so they (a report figure, not part of
the estimate) are skipped in that run.

Writes ``rows`` (indices into the recording of the predicted samples), ``tau`` (rows, 6, N m) and
``tau_measured`` (FIGAROH's own joint torque of those rows, to check the two tools read the same torque).
"""

from __future__ import annotations

import argparse
import contextlib
import io
import logging
import os
import sys
import warnings
from pathlib import Path

import numpy as np


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("example", help="figaroh-examples' examples/staubli_tx40 folder")
    parser.add_argument("out", help=".npz to write")
    parser.add_argument("--train-end", type=int, required=True)
    parser.add_argument("--coupled", action="store_true", help="call the example's coupling hook")
    args = parser.parse_args()
    example = Path(args.example).resolve()
    os.chdir(example)  # the example reads its config, URDF and data relative to its folder
    sys.path.insert(0, str(example.parents[1]))
    warnings.simplefilter("ignore")
    logging.disable(logging.WARNING)
    from examples.staubli_tx40.utils.staubli_tx40_tools import TX40Identification
    from figaroh.identification.base_identification import build_regressor_basic, build_regressor_reduced
    from figaroh.tools.robot import load_robot

    robot = load_robot("urdf/tx40_mdh_modified.urdf", package_dirs="../../models")
    config = "config/staubli_tx40_unified_config.yaml"
    with contextlib.redirect_stdout(io.StringIO()):
        ident = TX40Identification(robot, config)
        ident.initialize(truncate=(0, args.train_end))
        if args.coupled:
            ident.add_additional_parameters()
            ident._compute_validation_metrics = lambda *a, **k: None
        wls = ident.identif_config.get("wls", False)
        import inspect

        report = {"html_report": False} if "html_report" in inspect.signature(ident.solve).parameters else {}
        ident.solve(decimate=True, plotting=False, save_results=False, wls=wls, **report)  # versions differ
        whole = TX40Identification(robot, config)
        whole.process_data(truncate=None)
    data = whole.processed_data
    q, dq, ddq = data["positions"], data["velocities"], data["accelerations"]
    W = build_regressor_basic(robot, q, dq, ddq, ident.identif_config)
    if args.coupled:
        model = ident.model
        W = ident._add_coupling(W, model, ident.data, q.shape[0], model.nq, model.nv, model.njoints, q, dq, ddq)
    W_base = build_regressor_reduced(W, ident._idx_eliminated)[:, ident._base_indices]
    tau = (W_base @ ident.phi_base).reshape(-1, q.shape[0]).T  # the regressor stacks joint after joint
    n_raw = whole.raw_data["positions"].shape[0]
    step = n_raw * ident.identif_config["ts"] / (n_raw - 1)  # the example's stamps: linspace(0, n ts, n)
    rows = np.rint(np.asarray(data["timestamps"]).ravel() / step).astype(int)
    np.savez(args.out, rows=rows, tau=tau, tau_measured=np.asarray(data["torques"]))
    variant = "with its coupling hook" if args.coupled else "as it ships"
    print(f"FIGAROH {variant}: {len(ident.phi_base)} base parameters, rows {rows[0]}..{rows[-1]} predicted")


if __name__ == "__main__":
    main()
