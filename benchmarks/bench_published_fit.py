"""What the published pose's last fit does to its accuracy beside the oracle, on seeded synthetic problems.

    python -m benchmarks.bench_published_fit [--per-group 60] [--seed 101] [--jobs 2]
                                             [--out benchmarks/results/published_fit.md]

:func:`evopose.solver.published` ends every estimate with :func:`evopose.robust_fit.robust_fit` (the biweight sorts
the pairs, then least squares on those within the cut-off), made for camera frames whose false points lie within tau
of a mark. Here, on bench_confidence's problems (:func:`benchmarks.bench_confidence.make`) where EvoPose is confident
in the right basin and the solvePnP oracle (given the true correspondences) is in it too, the basin it judged is fitted
four ways from the same start, and each pose's median rotation and position error is set beside the oracle's:

* *polished*: the search's best as the verdict judged it (nearest-neighbour steps, least squares on the mutual pairs
  within tau);
* *published*: the robust fit, as shipped;
* *biweight only*: its first stage alone;
* *trimmed at the mixture's noise*: least squares on the mutual pairs within the cut-off of the noise that eq. (1)'s
  marginal likelihood gives at the start (:func:`evopose.mixture.mixture_fit`), no biweight stage.

The clutter here is spread over the image, so few false points lie near a mark: what the biweight costs where it has
little to sort, not what it saves on camera frames (``bench_photoreal_tracking``).
"""

from __future__ import annotations

import argparse
import os
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from .report import md_table, provenance, write_section

GROUPS = ("paper H1", "paper H2", "paper H1+H2", "paper H1 colours", "paper H2 colours", "paper H1+H2 colours",
          "telephoto")
FITS = ("polished", "published", "biweight only", "trimmed at the mixture's noise")


def fits(objective, start: np.ndarray) -> dict[str, np.ndarray]:
    """The four fits of the module docstring from ``start`` (6,), the basin the verdict judged."""
    from evopose.covariance import mutual_matches
    from evopose.mixture import false_shares, mixture_fit
    from evopose.robust_fit import cutoff_sigmas, irls_stage, residual_scale, robust_fit, view_cutoffs

    n_free = int(np.count_nonzero(objective.problem.bounds.free))
    taus = np.array(objective.taus, float)
    matches = mutual_matches(objective, start)
    out = {"polished": np.array(start, float), "published": robust_fit(objective, start)[0],
           "biweight only": irls_stage(objective, start, matches, True, view_cutoffs(matches, n_free, taus))}
    distance = np.linalg.norm(matches.residuals, axis=1)
    mixture = mixture_fit(objective, start, residual_scale(distance, n_free), false_shares(matches))
    if mixture is None:
        out["trimmed at the mixture's noise"] = out["published"]
    else:
        cutoffs = np.minimum(cutoff_sigmas(2 * len(distance) - n_free) * np.sqrt(mixture.sigma2), taus)
        out["trimmed at the mixture's noise"] = irls_stage(objective, start, matches, False, cutoffs)
    return out


def one(task: tuple[str, int, int]) -> dict | None:
    """Problem ``index`` of ``group``: each fit's rotation (deg) and position (m) errors and the oracle's, or None
    where EvoPose is not confident in the right basin or the oracle not in it."""
    import evopose.solver as solver
    from evopose import solve

    from .bench_confidence import make
    from .peers import pnp_oracle_views
    from .problems import in_true_basin, pose_errors

    group, seed, index = task
    sp = make(group, seed, index)
    judged = {}
    publish = solver.published

    def keep(objective, basin, verdict):   # the basin the verdict judged, as the published fit starts from it
        judged.update(objective=objective, basin=np.array(basin, float))
        return publish(objective, basin, verdict)

    solver.published = keep
    try:
        sol = solve(sp.problem, seed=index)
    finally:
        solver.published = publish
    oracle = pnp_oracle_views(sp)
    if not (sol.confident and in_true_basin(sp, sol.pose) and in_true_basin(sp, oracle.pose)):
        return None
    centre = sp.problem.model.points.mean(axis=0)

    def errors(pose: np.ndarray) -> tuple[float, float]:
        rot, pos = pose_errors(pose, sp.true_pose, sp.symmetries, centre)
        return float(np.rad2deg(rot)), float(pos)

    return {"group": group, "oracle": errors(oracle.pose),
            **{name: errors(pose) for name, pose in fits(judged["objective"], judged["basin"]).items()}}


def rows(records: list[dict]) -> list[list]:
    out = []
    for group in GROUPS:
        mine = [r for r in records if r["group"] == group]
        if not mine:
            continue
        oracle = np.median(np.array([r["oracle"] for r in mine]), axis=0)
        cells = [group, len(mine), f"{oracle[0]:.2f} / {100 * oracle[1]:.1f}"]
        for name in FITS:
            med = np.median(np.array([r[name] for r in mine]), axis=0)
            cells.append(f"{med[0]:.2f} ({med[0] / oracle[0]:.2f}x) / {100 * med[1]:.1f} ({med[1] / oracle[1]:.2f}x)")
        out.append(cells)
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--per-group", type=int, default=60)
    parser.add_argument("--seed", type=int, default=101)
    parser.add_argument("--jobs", type=int, default=min(2, os.cpu_count() or 1))
    parser.add_argument("--out", type=Path, default=Path("benchmarks/results/published_fit.md"))
    args = parser.parse_args(argv)
    t0 = time.time()
    todo = [(g, args.seed, i) for g in GROUPS for i in range(args.per_group)]
    with ProcessPoolExecutor(max_workers=args.jobs) as pool:
        records = [r for r in pool.map(one, todo, chunksize=4) if r is not None]
    command = (f"python -m benchmarks.bench_published_fit --per-group {args.per_group} --seed {args.seed} "
               f"--jobs {args.jobs}")
    header = ["group", "problems (confident, right basin, the oracle too)", "oracle: rotation deg / position cm",
              *[f"{name}: rotation / position (x the oracle's)" for name in FITS]]
    body = (f"Command: `{command}` ({provenance()}; {(time.time() - t0) / 60:.1f} min, {args.jobs} processes).\n\n"
            "Medians over the problems where EvoPose is confident in the right basin and the oracle is in it too; each "
            "fit from the basin the verdict judged (the module docstring of `benchmarks/bench_published_fit.py`).\n\n"
            + "\n".join(md_table(header, rows(records))) + "\n")
    write_section(args.out, "What the published pose's last fit does to its accuracy beside the oracle (synthetic)",
                  body)
    print(body)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
