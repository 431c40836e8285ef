"""When a search may end on a verdict: each search's verdict replayed at every generation, and stop rules tried on it.

    python -m benchmarks.bench_judged_stop [--per-group 30] [--absent 15] [--seed 101] [--jobs 2]
                                           [--out benchmarks/results/judged_stop.md]

:func:`evopose.solve` pauses its search once for a verdict on its best (:meth:`evopose.search.EvoPose.ready`,
:func:`evopose.solver.settles_search`). Which pause, and which verdicts end the search, were chosen here: on
bench_confidence's problems (:func:`benchmarks.bench_confidence.make`) every search runs with the pause off, one
generation at a time, and where its best basin has two or more supporters (or the search stops) the solution it
would publish there is judged (:func:`evopose.solver.solution_of`). A rule picks the first generation it pauses
at; the search ends there when the rule says so, else it runs to its own stop and pays for the wasted verdict too.
Each rule is compared with the searches run to their stop rules: confident, right basin, confident and wrong,
good (confident and precise), accurate, and the CPU time (search and verdicts).
"""

from __future__ import annotations

import argparse
import os
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from .report import md_table, provenance, write_section

#: Rules tried: (supporters, most starts when judged, what ends the search); "confident" is what solve does.
RULES = tuple((k, cap, ends) for ends in ("confident", "any verdict") for k in (2, 3, 5) for cap in (150, 300, None))


def replay(task: tuple[str, int, int]) -> dict:
    """One problem's search, generation by generation, with the verdict it would publish where it may pause."""
    from evopose import SearchOptions
    from evopose.loop import Evaluator, evolve
    from evopose.search import EvoPose
    from evopose.solver import settles_search, solution_of

    from .bench_confidence import make
    from .problems import in_true_basin, is_success, pose_errors

    group, seed, index = task
    sp = make(group, seed, index)
    absent = "absent" in sp.meta
    options = SearchOptions(judged_supporters=0)
    evo = EvoPose(sp.problem, options)
    state, evaluator, rng = evo.start(), Evaluator.for_search(sp.problem, options), np.random.default_rng(index)
    rows, searched = [], 0.0
    while True:
        t0 = time.process_time()
        run = evolve(evo, state, evaluator, until_generation=state.generation + 1, rng=rng)
        searched += time.process_time() - t0
        state, evaluator = run.state, run.evaluator
        row = {"starts": int(state.starts), "supporters": len(state.best_supporters), "searched": searched,
               "acceptable": bool(options.is_acceptable(state.best_match)), "finished": run.finished}
        if row["supporters"] >= 2 or run.finished:
            t1 = time.process_time()
            sol = solution_of(sp.problem, options, run, 0.0)
            row.update(judging=time.process_time() - t1, confident=bool(sol.confident), ends=settles_search(sol),
                       good=bool(sol.confident and sol.precise))
            if not absent:
                rot, pos = pose_errors(sol.pose, sp.true_pose, sp.symmetries, sp.problem.model.points.mean(axis=0))
                row.update(right=bool(in_true_basin(sp, sol.pose)), accurate=bool(is_success(rot, pos, sp.distance)))
        rows.append(row)
        if run.finished:
            return {"group": group, "index": index, "generations": rows}


def outcome(record: dict, rule: tuple) -> tuple[dict, float]:
    """The generation a rule ends ``record``'s search at (its own stop when it does not), and the CPU time spent."""
    k, cap, ends = rule
    rows, final = record["generations"], record["generations"][-1]
    paused = next((r for r in rows if "confident" in r and not r["finished"] and r["supporters"] >= k
                   and r["acceptable"] and (cap is None or r["starts"] <= cap)), None)
    if paused is None:
        return final, final["searched"] + final["judging"]
    if paused["ends"] or ends == "any verdict":
        return paused, paused["searched"] + paused["judging"]
    return final, final["searched"] + final["judging"] + paused["judging"]


COUNTS = ("confident", "right", "confident and wrong", "good", "accurate")


def counts(rows: list[dict]) -> dict:
    return {"confident": sum(r["confident"] for r in rows), "right": sum(r.get("right", False) for r in rows),
            "confident and wrong": sum(r["confident"] and not r.get("right", False) for r in rows),
            "good": sum(r["good"] for r in rows), "accurate": sum(r.get("accurate", False) for r in rows)}


def table(records: list[dict]) -> list[list]:
    full = [(r["generations"][-1], r["generations"][-1]["searched"] + r["generations"][-1]["judging"])
            for r in records]
    base, base_time = counts([f for f, _ in full]), sum(t for _, t in full)
    telephoto = [i for i, r in enumerate(records) if r["group"] == "telephoto"]
    base_tele = float(np.median([full[i][1] for i in telephoto])) if telephoto else float("nan")
    out = [["searched to the stop rules", "", "", *[base[c] for c in COUNTS], "1.00", "1.00"]]
    for rule in RULES:
        ended = [outcome(r, rule) for r in records]
        got = counts([row for row, _ in ended])
        tele = float(np.median([ended[i][1] for i in telephoto])) / base_tele if telephoto else float("nan")
        out.append([f"{rule[0]} supporters", "any" if rule[1] is None else f"<= {rule[1]}", rule[2],
                    *[f"{got[c]} ({got[c] - base[c]:+d})" for c in COUNTS],
                    f"{sum(t for _, t in ended) / base_time:.2f}", f"{tele:.2f}"])
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--per-group", type=int, default=30, help="problems per bench_confidence group with a target")
    parser.add_argument("--absent", type=int, default=15, help="absent-target problems per scale and kind")
    parser.add_argument("--seed", type=int, default=101, help="101: the set the rule was chosen on")
    parser.add_argument("--jobs", type=int, default=min(2, os.cpu_count() or 1))
    parser.add_argument("--out", type=Path, default=Path("benchmarks/results/judged_stop.md"))
    args = parser.parse_args(argv)
    from .bench_confidence import tasks

    t0 = time.time()
    todo = tasks(args.per_group, args.absent, args.seed)
    with ProcessPoolExecutor(max_workers=args.jobs) as pool:
        list(pool.map(replay, [("telephoto", args.seed, 0)] * args.jobs))  # compile and warm the kernels
        records = list(pool.map(replay, todo, chunksize=2))
    command = (f"python -m benchmarks.bench_judged_stop --per-group {args.per_group} --absent {args.absent} "
               f"--seed {args.seed} --jobs {args.jobs}")
    header = ["supporters when judged", "starts when judged", "what ends the search", *COUNTS,
              "CPU time (all problems)", "median CPU time (telephoto group)"]
    minutes = (time.time() - t0) / 60
    body = (f"Command: `{command}` ({provenance()}; {minutes:.1f} min, {args.jobs} processes).\n\n"
            f"{len(records)} problems of bench_confidence (seed {args.seed}), absent targets included; counts over "
            "all of them, times as a share of the searches run to their stop rules (the verdicts at a pause that "
            "did not end the search counted).\n\n" + "\n".join(md_table(header, table(records))) + "\n")
    write_section(args.out, "When a search may end on a verdict: each search's verdict replayed per generation",
                  body)
    print(body)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
