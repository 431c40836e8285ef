"""The paper's Tables I and II and ours beside them: the paper's numbers, our rows found among the results, the
table lines, and the cells where ours exceed the paper's. Read by the report (:mod:`agents.experiments.report`) and
its Table II on a rendered dataset (:mod:`agents.experiments.photoreal`)."""

from __future__ import annotations

import math

#: Paper, Table I: roll, pitch, yaw error (deg), X, Y, Z error (cm), each (mean, σ); time (s).
PAPER_TABLE_I = {
    "EvoPose": ((20.6, 15.2), (1.8, 2.4), (2.9, 3.6), (5, 4.6), (9, 6.9), (16, 15), 3.2),
    "EvoPose+IMU": ((0.1, 0.1), (0.1, 0.1), (0.1, 0.1), (6, 4.2), (9, 7.1), (15, 16), 2.3),
}
#: Paper, Table II: roll, pitch, yaw error (deg), X, Y, Z error (m), each (mean, σ); time (s; H2: "> 5").
PAPER_TABLE_II = {
    "H1": ((1.3, 1.7), (1.0, 2.1), (0.1, 0.3), (1.0, 0.4), (0.5, 0.2), (2.3, 1.8), 2.3),
    "H2": ((1.1, 1.6), (1.0, 3.3), (0.5, 1.3), (1.0, 0.7), (1.2, 1.3), (2.2, 3.3), 5.0),
    "H1 + H2": ((1.1, 1.8), (0.1, 0.3), (0.0, 0.1), (0.1, 0.1), (0.2, 0.2), (0.9, 0.4), 1.6),
    "H1 + hint": ((0.6, 1.0), (1.0, 1.8), (0.0, 0.0), (0.9, 0.3), (0.3, 0.1), (1.6, 0.9), 0.6),
    "H2 + hint": ((0.2, 0.1), (0.1, 0.5), (0.0, 0.1), (0.6, 0.2), (0.7, 0.2), (0.7, 0.4), 1.3),
}
ANGLES, AXES = ("roll", "pitch", "yaw"), ("x", "y", "z")
#: Half the last digit Table II prints (degrees and metres to one decimal).
PAPER_ROUNDING = 0.05
#: Table II's rows: (label, scenario, vehicle).
TABLE_II_ROWS = (("H1", "exp2-solo", "H1"), ("H2", "exp2-solo", "H2"), ("H1 + H2", "exp2a-features", "H1"),
                 ("H1 + hint", "exp2b-hints", "H1"), ("H2 + hint", "exp2b-hints", "H2"))


def cell(mean: float, sd: float, digits: int) -> str:
    return "-" if mean is None or math.isnan(mean) else f"{mean:.{digits}f} ({sd:.{digits}f})"


def our_row(label: str, r: dict, scale: float, digits: tuple[int, int], paper_time_s: float) -> str:
    cells = [cell(r[n], r[f"{n}_sd"], digits[0]) for n in ANGLES]
    cells += [cell(r[n] * scale, r[f"{n}_sd"] * scale, digits[1]) for n in AXES]
    cells.append(cell(r["first_good_s"], r["first_good_sd"], 3)
                 + (f" ({paper_time_s / r['first_good_s']:.0f}x faster)" if r["first_good_s"] > 0 else ""))
    return f"| {label} | ours | " + " | ".join(cells) + " |"


def paper_row(label: str, values: tuple) -> str:
    cells = [f"{m:g} ({s:g})" for m, s in values[:6]]
    time_s = values[6]
    cells.append(("> 5" if label == "H2" else f"{time_s:g}"))
    return f"| {label} | paper | " + " | ".join(cells) + " |"


HEADER = ("| {what} | source | roll ° (σ) | pitch ° (σ) | yaw ° (σ) | X {u} (σ) | Y {u} (σ) | Z {u} (σ) | "
          "time to good pose, s |\n|---|---|---|---|---|---|---|---|---|")


def find_row(result_rows: list[dict], scenario: str, vehicle: str, world: str | None = None) -> dict | None:
    return next((r for r in result_rows if r["scenario"] == scenario and r["vehicle"] == vehicle
                 and (world is None or r["world"] == world)), None)


def find_variant(result_rows: list[dict], variant: str, vehicle: str) -> dict | None:
    return next((r for r in result_rows if r["variant"] == variant and r["vehicle"] == vehicle), None)


def table_ii(result_rows: list[dict], world: str) -> list[str]:
    lines = [HEADER.format(what="cameras", u="m")]
    for label, scenario, vehicle in TABLE_II_ROWS:
        r = find_row(result_rows, scenario, vehicle, world)
        if r:
            lines.append(our_row(label, r, 1, (2, 4), PAPER_TABLE_II[label][6]))
        lines.append(paper_row(label, PAPER_TABLE_II[label]))
    return lines


def above_paper(result_rows: list[dict], world: str) -> list[str]:
    """The cells of Table II on ``world`` whose mean error exceeds the paper's (or that have no good pose), as
    ``"H2 pitch 4.05 > 1 deg"``: at least the paper's value plus half its last printed digit
    (:data:`PAPER_ROUNDING`). A row not run is not listed."""
    out = []
    for label, scenario, vehicle in TABLE_II_ROWS:
        r = find_row(result_rows, scenario, vehicle, world)
        if r is None:
            continue
        for (name, unit), (paper, _) in zip([(a, "deg") for a in ANGLES] + [(x, "m") for x in AXES],
                                            PAPER_TABLE_II[label][:6]):
            ours = r[name]
            if ours is None or math.isnan(ours):
                out.append(f"{label} {name}: no good pose")
                break
            if ours >= paper + PAPER_ROUNDING:  # the paper prints one decimal: "0.0" is under 0.05
                out.append(f"{label} {name} {ours:.3g} > {paper:g} {unit}")
    return out
