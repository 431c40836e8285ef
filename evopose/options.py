"""Tuning of the search (:class:`SearchOptions`) and what it calls an acceptable or a close match."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .fitness import FitnessKind, Match
from .trust import ConfidenceRules
from .weights import VIEW_WEIGHTINGS, ViewWeighting


@dataclass(frozen=True)
class SearchOptions:
    """Tuning of the search; the defaults solve the benchmark problems.

    Match thresholds are on :class:`evopose.fitness.Match`: ``mismatch`` (eq. 4 over its no-match value)
    and ``unmatched`` (share of visible marks without a one-to-one match), both 0 when perfect.

    Attributes
    ----------
    fitness : "mutual" | "robust" | "paper"
        Eq. (1)'s distance made one to one and bounded (the root mean square over mutual nearest pairs, tau for
        a point without one: :func:`evopose.kernels.mutual_row`), the two-sided bounded mean of issue 2, or the
        paper's plain eq. (1). "mutual" finds the right basin more often at the paper's image scale (issue 11:
        on seeded Pioneer problems at 25 px, 78 % against 62 % for "robust") and as often at the telephoto scale.
    tau : float or None
        Truncation distance in pixels (bounded kinds); automatic per view when None (:func:`evopose.fitness.auto_tau`).
    population : int
        ``mu``, individuals kept between generations.
    offspring : int
        ``lambda``, new individuals per generation.
    immigrants : float
        Fraction of the offspring that are fresh random starts.
    screening : int
        Fresh starts are drawn this many times over and the best by a coarse fitness kept.
    refine_steps : int
        Annealed soft-matching steps of the local refinement per new individual
        (0 gives the paper's plain EA, without refinement).
    max_generations, max_evaluations : int
    time_budget : float or None
        Seconds of wall time.
    good_fitness : float or None
        Stop as soon as the best fitness is at or below this value.
    consensus : int
        Stop when the best basin was reached from this many independent starts (0: never),
        at least ``min_starts`` starts were made, and its match is acceptable: mismatch or unmatched
        share at most ``acceptable_mismatch``.
    acceptable_mismatch : float
    min_starts : int
        Independent (screened, refined) random starts before the consensus or stall rule may stop
        (times up to 4 when the problem has fewer than ``REFERENCE_PAIRS`` model x image point pairs)...
    close_mismatch : float
        ...when the best match is close: mismatch at most this, or at most ``close_unmatched``
        of the best pose's visible marks lack a one-to-one image match; otherwise
    close_unmatched : float
    min_starts_loose : int
        starts are needed (a poor best match may be a wrong basin: search longer).
    settled_starts, settled_supporters, settled_ratio : int, int, float
        The search stops ("consensus") before ``min_starts`` once its answer is settled
        (:meth:`evopose.search.EvoPose.settled`): at least ``settled_starts`` starts (times the same factor), the
        best basin's match close and reached from ``settled_supporters`` independent starts, and the best unimproved
        since ``1 / settled_ratio`` of the starts. 0 supporters: never.
    judged_supporters, judged_starts : int
        :func:`evopose.solver.solve` judges its best once, the first generation its basin has been reached from
        ``judged_supporters`` independent starts (and matches acceptably) while at most ``judged_starts`` were made (a
        common basin: the first two generations' 96 + 51): a confident verdict ends the search there ("judged":
        :func:`evopose.solver.settles_search`), any other lets it run on by the rules above. A rarer best is judged
        only where the rules stop: a verdict weighs the rivals the search has found, and a rugged landscape hides
        them longer. 0 supporters, or ``consensus`` 0: never (a search in slices, :mod:`evopose.cooperative`, is never
        paused).
    patience : int
        Stop ("stalled") when the best has not improved for this many generations after ``min_starts``.
    min_generations : int
    view_reject : float or None
        Step-function weight rule of eq. (4): a view whose term exceeds this (fraction of its
        tau for the bounded fitness kinds, pixels for the paper's) gets weight 0. None disables it.
        The default suits "mutual": at the paper's scale a right view reaches 0.73 of tau (2 px noise, 30 %
        clutter), a view of clutter alone 0.69-0.83, at the telephoto scale 0.67 and 0.88 or more
        ("robust" used 0.6).
    view_weights : "equal" | "step" | "adaptive"
        How eq. (4)'s weights follow the views during a search (:mod:`evopose.weights`): never ("equal", the
        views' own ``W_k``), the paper's step rule at ``view_reject`` ("step"), or the step rule and a bounded
        graded reliability per view from its own evidence (residual, marks matched one to one against its image
        points, the information of its matches) ("adaptive").
    same_position : float
        Two poses are in the same basin when their positions differ by less than this
        fraction of the target distance...
    same_rotation : float
        ...and their rotations by less than this many radians.
    confidence : ConfidenceRules
        When a solution is called confident (:func:`evopose.trust.assess`) and the other rules of the verdict.
    """

    fitness: FitnessKind = "mutual"
    tau: float | None = None
    population: int = 32
    offspring: int = 64
    immigrants: float = 0.8
    screening: int = 8
    refine_steps: int = 10
    max_generations: int = 150
    max_evaluations: int = 2_000_000
    time_budget: float | None = None
    good_fitness: float | None = None
    consensus: int = 2
    acceptable_mismatch: float = 0.5
    min_starts: int = 256
    close_mismatch: float = 0.3
    close_unmatched: float = 0.1
    min_starts_loose: int = 1024
    settled_starts: int = 128
    settled_supporters: int = 5
    settled_ratio: float = 2.0
    judged_supporters: int = 3
    judged_starts: int = 150
    patience: int = 6
    min_generations: int = 1
    view_reject: float | None = 0.8
    view_weights: ViewWeighting = "step"
    same_position: float = 0.02
    same_rotation: float = np.deg2rad(3.0)
    confidence: ConfidenceRules = ConfidenceRules()

    def __post_init__(self) -> None:
        if self.screening < 1:
            raise ValueError(f"screening must be >= 1, got {self.screening}")
        if self.population < 2 or self.offspring < 1:
            raise ValueError("population must be >= 2 and offspring >= 1")
        if not 0.0 <= self.immigrants <= 1.0:
            raise ValueError(f"immigrants must be a fraction in [0, 1], got {self.immigrants}")
        if self.refine_steps < 0 or self.max_generations < 1:
            raise ValueError("refine_steps must be >= 0 and max_generations >= 1")
        if self.view_weights not in VIEW_WEIGHTINGS:
            raise ValueError(f"view_weights must be one of {', '.join(VIEW_WEIGHTINGS)}, got {self.view_weights!r}")

    def is_acceptable(self, match: Match) -> bool:
        """Mismatch or unmatched share within ``acceptable_mismatch`` (always True when the mismatch is unknown:
        the paper's eq. 1 has no no-match value to judge by): what a search may stop on, and converge with."""
        return (match.mismatch is None or match.mismatch <= self.acceptable_mismatch
                or match.unmatched <= self.acceptable_mismatch)

    def is_close(self, match: Match) -> bool:
        """Mismatch within ``close_mismatch`` or unmatched share within ``close_unmatched`` (True when the
        mismatch is unknown): a search with a close best needs ``min_starts`` starts, else ``min_starts_loose``;
        when a search's best first matched closely is the paper's "time to a good pose"."""
        return (match.mismatch is None or match.mismatch <= self.close_mismatch
                or match.unmatched <= self.close_unmatched)
