#!/usr/bin/env python3
"""Reference R-hat / ESS values for `crates/study/tests/study.rs` from ArviZ.

Rerun (from the repository root):
    python3 -m pip install arviz==0.23.4 numpy
    python3 tools/make_mcmc_diagnostics_fixtures.py crates/study/tests/fixtures/study/diagnostics.json

Makes a few sets of 4 chains (AR(1) series of different autocorrelation, one set with a shifted
chain that has not mixed, one with heavy ties), stores the draws, and ArviZ's
`rhat(method="rank")`, `ess(method="bulk")` and `ess(method="tail")` of each.
"""
import json
import sys
import warnings

import numpy as np

warnings.filterwarnings("ignore")
import arviz as az  # noqa: E402


def ar1(rng, chains, draws, phi, shift=None):
    x = np.zeros((chains, draws))
    e = rng.standard_normal((chains, draws))
    for t in range(1, draws):
        x[:, t] = phi * x[:, t - 1] + e[:, t]
    if shift is not None:
        x[0] += shift
    return x


def main(out):
    rng = np.random.default_rng(7)
    sets = {
        "iid": ar1(rng, 4, 301, 0.0),
        "ar_0.5": ar1(rng, 4, 300, 0.5),
        "ar_0.9": ar1(rng, 4, 400, 0.9),
        "shifted": ar1(rng, 4, 250, 0.3, shift=1.5),
        "ties": np.round(ar1(rng, 4, 200, 0.2)),
    }
    cases = []
    for name, x in sets.items():
        x = np.round(x, 5)  # stored values are exactly the ones analysed
        cases.append({
            "name": name,
            "chains": x.tolist(),
            "rhat_rank": float(az.rhat(x, method="rank")),
            "ess_bulk": float(az.ess(x, method="bulk")),
            "ess_tail": float(az.ess(x, method="tail")),
        })
    with open(out, "w") as f:
        json.dump({"generator": "tools/make_mcmc_diagnostics_fixtures.py", "arviz": az.__version__, "cases": cases}, f)


if __name__ == "__main__":
    main(sys.argv[1])
