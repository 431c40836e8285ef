"""An agent's native thread pools: one BLAS thread per agent process.

numpy's OpenBLAS starts a worker per core and, after each call large enough to be split (the covariance's
Monte Carlo moments, a ``(16384, 6) @ (6, 6)`` product), that worker busy-waits for the next one. In an agent,
which computes every few milliseconds, it never went back to sleep: `python -m benchmarks.bench_blas_threads`
(BENCHMARKS.md) repeats that call 200 times a second and measures 1.46-1.52 cores for the process with the
default pool against 0.51-0.53 with one thread, the calls themselves taking 0.45-0.52 in both. The agents of a pair
missed camera ticks and sent fewer hints. An agent's arrays are small and it has threads of its own (frame
loop, receivers): BLAS gains nothing from more than one thread there.
"""

from __future__ import annotations

from threadpoolctl import threadpool_limits

#: BLAS threads of an agent process.
AGENT_BLAS_THREADS = 1


def limit_blas_threads(threads: int = AGENT_BLAS_THREADS) -> None:
    """Cap the BLAS libraries loaded in this process at ``threads`` threads (for the rest of the process)."""
    threadpool_limits(limits=threads, user_api="blas")


__all__ = ["AGENT_BLAS_THREADS", "limit_blas_threads"]
