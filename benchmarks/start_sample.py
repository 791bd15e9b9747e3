"""One Phase from the best of two starts against the blended guess alone, paired case by case.

Run:    .venv/bin/python benchmarks/start_sample.py STORE

STORE holds `benchmarks/suites/start-sample.toml`'s cases: OP-DC and OP-DM with the strategy option
start = "best" (each step solved from the blended guess and from the grid-continuation start, the cheaper verified
motion kept), and the same cases from the blended guess alone ("OP-DC blended", "OP-DM blended"). Pairs them by
experiment, transcription and N, and prints each pair's verified ACOTs (an unverified walk has none), the paired
change, the case times, and the rule's counts for a change that moves results: the mean paired change and the walks
complete and verified on either side.
"""

from __future__ import annotations

import sys

import pandas as pd

from gaitbench.run.store import load_results

KEY = ["experiment", "method", "N"]
BLENDED = " blended"
"""The suffix of the blended arm's method labels."""


def verified_acots(cases: pd.DataFrame) -> pd.DataFrame:
    """Per case: the verified ACOT of a complete, verified walk (else NaN), whether it is one, and its case time."""
    complete = (cases["status"] == "solved") & (cases["stop_cause"] == "complete")
    verified = complete & cases["verified"].fillna(False).astype(bool)
    return cases.assign(verified_walk=verified, acot=cases["acot"].where(verified))[
        KEY + ["acot", "verified_walk", "wall_time_s"]]


def paired(store: str) -> pd.DataFrame:
    """The sample's cases with both ACOTs and the relative change, best against blended."""
    cases = verified_acots(load_results(store))
    blended = cases["method"].str.endswith(BLENDED)
    best = cases[~blended]
    other = cases[blended].assign(method=cases["method"].str.removesuffix(BLENDED))
    pairs = best.merge(other, on=KEY, suffixes=("_best", "_blended"), how="outer")
    pairs["change"] = pairs["acot_best"] / pairs["acot_blended"] - 1
    return pairs.sort_values(KEY).reset_index(drop=True)


def main(argv: list[str]) -> None:
    pairs = paired(argv[0])
    print(pairs.to_string(float_format=lambda value: f"{value:.4f}"))
    both = pairs["change"].dropna()
    print(f"\npairs with both verified: {len(both)} of {len(pairs)}; mean change {both.mean():+.1%}, "
          f"median {both.median():+.1%}, lower in {(both < -1e-6).sum()}, higher in {(both > 1e-6).sum()}")
    print(f"complete and verified: best {int(pairs['verified_walk_best'].fillna(False).sum())}, "
          f"blended {int(pairs['verified_walk_blended'].fillna(False).sum())}; case time: best "
          f"{pairs['wall_time_s_best'].sum():,.0f} s, blended {pairs['wall_time_s_blended'].sum():,.0f} s")


if __name__ == "__main__":
    main(sys.argv[1:])
