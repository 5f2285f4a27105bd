"""Temporal consistency: a loop closure only after K consecutive verified candidates agree with
the motion (ORB-SLAM3 and pyslam ask for 3 consistent detections).

Candidates arrive in query order, one per query at most. A verified candidate (q, m) agrees with
the previous one (q0, m0) of the chain when the query advanced (q > q0) and the match advanced
with it, forwards or backwards (a reverse revisit): |(m - m0) - d (q - q0)| <= tol frames, d = +1
or -1 the chain's direction (either until the chain's matches have moved by more than tol). An
agreeing candidate extends the chain; a verified one that does not agree starts a new chain; a
rejected one ends it. A closure is declared for every candidate of a chain from its K-th on.
"""
from __future__ import annotations

from greenloop.util.checks import positive_int

DEFAULT_K = 3      # consecutive agreeing verified candidates (ORB-SLAM3's 3 consistent detections)
DEFAULT_TOL = 5    # frames the match may drift from the query's motion between two candidates


class Consistency:
    """The chain of agreeing verified candidates (module doc). k: candidates a closure needs (>= 1);
    tol: frames of drift allowed between consecutive candidates (>= 0). State: ``chain``, the
    (query, match) pairs of the current chain (its last k kept), ``length`` (candidates in it) and
    ``direction`` (+1, -1, or 0 while undecided)."""

    def __init__(self, k: int = DEFAULT_K, tol: int = DEFAULT_TOL):
        self.k = positive_int("k", k)
        self.tol = positive_int("tol", tol, minimum=0, unit="frames")
        self.reset()

    def reset(self) -> None:
        """Forget the chain (a new recording, or after a jump)."""
        self.chain: list[tuple[int, int]] = []
        self.direction = 0
        self.length = 0
        self._start = 0          # the match frame the chain began at

    def _agrees(self, q: int, m: int) -> bool:
        """True where (q, m) continues the chain (module doc)."""
        q0, m0 = self.chain[-1]
        dq, dm = q - q0, m - m0
        if dq <= 0:
            return False
        dirs = (self.direction,) if self.direction else (1, -1)
        return any(abs(dm - d * dq) <= self.tol for d in dirs)

    def update(self, query: int, match: int, accepted: bool) -> bool:
        """Feed one candidate: query and match frame numbers (int), accepted: its verification
        held. Returns True when a closure is declared for it (the chain holds >= k candidates)."""
        q, m = int(query), int(match)
        if not accepted:
            self.reset()
            return False
        if self.chain and self._agrees(q, m):
            self.length += 1
            if not self.direction and abs(m - self._start) > self.tol:
                self.direction = 1 if m > self._start else -1
            self.chain = (self.chain + [(q, m)])[-self.k:]
        else:
            self.chain, self.direction, self.length, self._start = [(q, m)], 0, 1, m
        return self.length >= self.k
