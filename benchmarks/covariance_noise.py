"""Why the published covariance is too tight on some answers (issue 35): the noise it is scaled by, read at the pose
fitted to the same points, against the true noise; and the same covariance with the true noise.

    NUMBA_NUM_THREADS=1 python -m benchmarks.covariance_noise [--seed 7] [--per-group 60] [--regression]
                                                           [--out benchmarks/results/covariance_noise.md]

An analysis, not a figure to hold: nothing in the solver is chosen on it. On the seeded problems of
``benchmarks.bench_confidence`` (paper H1, H2, H1+H2, telephoto; :func:`benchmarks.bench_confidence.make`) each
solve's published covariance (:func:`evopose.mixture.mixture_covariance`, eq. (1)'s marginal likelihood, Louis'
observed information) is recomputed at the published pose in three ways, over the confident answers
(``--regression``: on the fixed problem set of ``benchmarks.solver_regression`` instead, printed only):

* as published: the noise ``sigma`` fitted by EM at the published pose (:func:`evopose.mixture.mixture_fit`);
* with the true noise: the same observed information at the problem's own ``sigma`` (the generator's);
* the noise EM finds at the *true* pose (no fit: the degrees-of-freedom correction undone), which says whether the
  low noise comes from the data or from the pose fitted to them.

"Rotation (position) beyond 95 %": the share of confident answers whose error's Mahalanobis distance over the 3x3
rotation (position) block exceeds chi-squared(3)'s 95 % quantile (7.81): 5 % for a calibrated covariance (a little
more with few pairs, the noise being estimated). "1-sigma coverage" as in ``bench_confidence``.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from .report import md_table, provenance, write_section

GROUPS = ("paper H1", "paper H2", "paper H1+H2", "telephoto")
#: chi-squared with 3 degrees of freedom, 95 % quantile.
CHI2_3_95 = 7.815
NOISE_BANDS = ((0.5, 1.0), (1.0, 1.5), (1.5, 2.01))
#: What the analysis found (shown under the tables; the seed-101 and regression-set figures from the same recipe).
FOUND = (
    "What it found (issue 35; nothing in the solver changed). (1) The noise EM fits at the published pose understates "
    "the true noise where it nears the marks' spacing (1.5-2 px at the paper's scale, marks 3-5 px apart: median 0.83 "
    "of it, a tenth of the answers under 0.54), while at the true pose it finds 0.89 (0.78): the pose fitted to the "
    "points also chose which mark each point pairs with, and took up more of the noise than the n_free coordinates the "
    "correction gives back. Scaled by the true noise, the same observed information leaves 4-11 % of the confident "
    "rotations past the 95 % ellipsoid instead of 10-22 % (`--seed 101`: H1 33 -> 20 %, H2 19 -> 8 %, H1+H2 19 -> 4 %, "
    "telephoto 28 -> 12 %; `--regression`: the paper-scale problems 40 -> 0 %, the telephoto boxes 18 -> 0 %). "
    "(2) The regression set's confident misses (telephoto boxes 2, 14, 26, paper-scale problems 0, 2, 3, 8, 14; "
    "4.5-9.3 deg off) all lie within the 95 % rotation ellipsoid of the covariance at the true noise (Mahalanobis^2 "
    "1.8-6.5); with the fitted noise three do not: paper 0 (1.85 px fitted as 0.83 px: rotation sigmas 1.8-2.8 deg "
    "against 4.4-7.2), telephoto 26 (1 px as 0.52 px) and paper 8 (0.74 px as 0.62 px). The others were not "
    "overconfident: a rotation 5-8.4 deg off (an angle: the norm over three axes) with 2-5 deg per axis is ordinary. "
    "All eight are imprecise (the paper-scale ones are one camera's), so none was good. (3) The 1-sigma coverage "
    "misses of the confidence section at seed 7 (paper H1 x/y/z 48/48/43 %, H2 89/83/83 %) are sampling: 23 and 18 "
    "confident "
    "answers, and one camera's position error lies along its line of sight, so x, y and z are inside or outside "
    "together (x and z agree on 92-96 % of the answers): one draw per answer, and 11 of 23 has a 95 % interval of "
    "29-67 %. Seed 101 reads 67/70/67 % and 54/54/54 % for the same groups; both seeds pooled 58/60/57 % and "
    "68/66/66 %. (4) Tried on seed 101, not kept: the fit's effective parameters tr(I_c I_o^-1) as the noise's "
    "lost degrees of freedom (stays ~6: at the low fitted noise the responsibilities are 0 or 1), Student's t "
    "(nu / (nu - 2): H1 33 -> 23 %, H1+H2 19 -> 19 %), the noise as a seventh parameter of the observed information "
    "(its coupling with the pose, a Schur complement: rotation sigmas x1.00 at the median), a prior on the noise at "
    "POINT_NOISE_PX with 4-8 degrees of freedom (H1 33 -> 17-23 %, H1+H2 19 -> 19-21 %, telephoto 28 -> 24 %; held "
    "out on seed 7 with 4: H1 22 -> 17 %, H2 22 -> 11 %, H1+H2 and telephoto unchanged; it would also widen the "
    "sub-pixel covariances of camera frames), EM started from a wider noise (the same fixed point). All of these "
    "are local, and a fit that chose its pairs is a fixed point of each: at the answer the points fit the low "
    "noise. A frame alone does not tell it; knowledge from outside the frame would (the camera's noise fused over "
    "its confident frames, or stated per camera). The wrong-basin confident answers behind the confidence section's "
    "96.5 % precision are imprecise already and mostly ones where eq. (1) prefers the wrong pose; the covariance "
    "enters `confident` only through the distinct-rival test.")


def _information_at(objective, pose: np.ndarray, sigma2: float, shares: np.ndarray) -> np.ndarray:
    """The published covariance's recipe (:func:`evopose.mixture.mixture_covariance`) at a given noise ``sigma2``."""
    from evopose.covariance import from_information
    from evopose.mixture import mixture_information, view_statistics, view_terms

    free = objective.problem.bounds.free
    terms = [(k, float(objective.weights[k]), view_terms(objective, pose, k, free))
             for k in range(objective.n_views) if objective.weights[k] > 0]
    terms = [(k, w, t) for k, w, t in terms if t is not None]
    info = mixture_information(view_statistics(terms, sigma2, shares), sigma2, int(np.count_nonzero(free)))
    values, vectors = np.linalg.eigh(info)
    info = (vectors * np.clip(values, 0.0, None)) @ vectors.T
    return from_information(objective, pose, info, sigma2, 0).matrix


def one(group: str, seed: int, index: int, sp=None) -> dict:
    """Solve problem ``index`` of ``group`` (``sp``, a :class:`benchmarks.problems.SyntheticProblem`, when given);
    its errors and the three noises and two covariances of the module docstring."""
    from evopose import solve
    from evopose.covariance import mutual_matches
    from evopose.fitness import PoseObjective
    from evopose.mixture import false_shares, mixture_fit
    from evopose.robust_fit import residual_scale

    from .bench_confidence import make, parameter_errors

    sp = make(group, seed, index) if sp is None else sp
    sol = solve(sp.problem, seed=index)
    rec = {"group": group, "index": index, "noise": float(sp.noise), "confident": bool(sol.confident)}
    if not sol.confident or not np.all(np.isfinite(sol.covariance)):
        return rec
    objective = PoseObjective(sp.problem).with_weights(sol.view_weights)
    n_free = int(np.count_nonzero(objective.problem.bounds.free))
    matches = mutual_matches(objective, sol.pose)
    shares = false_shares(matches)
    start = residual_scale(np.linalg.norm(matches.residuals, axis=1), n_free)
    at_truth = mixture_fit(objective, sp.true_pose, start, shares)
    rec.update(errors=parameter_errors(sp, sol.pose), published=np.asarray(sol.covariance),
               sigma_published=float(np.sqrt(sol.confidence.covariance.residual_variance)),
               true_noise=_information_at(objective, sol.pose, float(sp.noise) ** 2, shares),
               sigma_at_truth=None if at_truth is None else float(np.sqrt(
                   at_truth.sigma2 * (2 * at_truth.weight - n_free) / (2 * at_truth.weight))))
    return rec


def _beyond(recs: list[dict], key: str, block: slice) -> float:
    out = []
    for r in recs:
        e, cov = np.asarray(r["errors"])[block], r[key][block, block]
        keep = np.diag(cov) > 0
        out.append(float(e[keep] @ np.linalg.pinv(cov[np.ix_(keep, keep)]) @ e[keep]) > CHI2_3_95)
    return 100.0 * float(np.mean(out))


def _coverage(recs: list[dict], key: str) -> str:
    inside = np.array([np.abs(r["errors"]) <= np.sqrt(np.clip(np.diag(r[key]), 0, None)) for r in recs])
    return " / ".join(f"{100 * c:.0f}" for c in inside.mean(axis=0))


def _ratio(recs: list[dict], key: str) -> str:
    q = np.array([r[key] / r["noise"] for r in recs if r.get(key) is not None])
    return f"{np.median(q):.2f} ({np.quantile(q, 0.1):.2f})" if len(q) else "n/a"


def markdown(records: list[dict], args: argparse.Namespace, seconds: float) -> str:
    lines = [f"Command: `NUMBA_NUM_THREADS=1 python -m benchmarks.covariance_noise --seed {args.seed} --per-group "
             f"{args.per_group}` ({provenance()}; {seconds / 60:.1f} min). "
             + " ".join(__doc__.split("\n\n")[2].split()), "", __doc__.split("\n\n")[3].replace("\n  ", " "), "",
             " ".join(__doc__.split("\n\n")[4].split()), ""]
    header = ["group", "confident", "covariance", "rotation beyond 95 %", "position beyond 95 %",
              "1-sigma coverage x / y / z / roll / pitch / yaw (%)"]
    rows = []
    for g in dict.fromkeys(r["group"] for r in records):
        recs = [r for r in records if r["group"] == g and "errors" in r]
        if not recs:
            continue
        for name, key in (("as published", "published"), ("with the true noise", "true_noise")):
            rows.append([g, len(recs), name, f"{_beyond(recs, key, slice(3, 6)):.0f} %",
                         f"{_beyond(recs, key, slice(0, 3)):.0f} %", _coverage(recs, key)])
    lines += md_table(header, rows) + [""]
    lines += ["Fitted noise over the true one, median (10th percentile), confident answers:", ""]
    rows = []
    for lo, hi in NOISE_BANDS:
        recs = [r for r in records if "errors" in r and lo <= r["noise"] < hi]
        rows.append([f"{lo}-{min(hi, 2.0)} px", len(recs), _ratio(recs, "sigma_published"),
                     _ratio(recs, "sigma_at_truth")])
    lines += md_table(["true noise", "confident", "EM at the published pose", "EM at the true pose"], rows)
    lines += ["", FOUND]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=7)
    parser.add_argument("--per-group", type=int, default=60)
    parser.add_argument("--regression", action="store_true", help="the solver regression set instead (printed only)")
    parser.add_argument("--out", type=Path, default=Path("benchmarks/results/covariance_noise.md"))
    args = parser.parse_args(argv)
    t0 = time.perf_counter()
    if args.regression:
        from .solver_regression import suite

        records = [one(g, 0, i, sp) for g, problems in suite().items() for i, sp in enumerate(problems)]
        print("\n".join(markdown(records, args, time.perf_counter() - t0).split("\n")[6:-2]))
        return 0
    records = [one(g, args.seed, i) for g in GROUPS for i in range(args.per_group)]
    text = markdown(records, args, time.perf_counter() - t0)
    write_section(args.out, "Covariance: the noise it is scaled by, fitted and true (an analysis)", text)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
