"""The departed-client watch's bookkeeping, apart from rclpy: when the node may take a
kind of request's clients (service, action) for gone.

rclpy tells a server neither who sent a request nor when a caller left, only how many
clients the graph holds; the node reads that count every ``WATCH_PERIOD`` s
(:mod:`.node`). A kind's clients are gone when the graph has shown one while its requests
were active (seen) and then shows none on ``SIGHTINGS`` checks in a row (a client's request
writer is briefly absent while it reconnects). Counting from the request instead cancelled
live callers: a new client's request can arrive before the graph shows the client (the
graph comes from each participant's discovery messages, which can trail the request), and
the full test suite once got "the client left" 0.26 s after a fresh client's request. A
client that leaves before the graph ever showed it is not noticed: its plans run to their
time bound.
"""

from __future__ import annotations

from typing import Hashable, Iterable

__all__ = ["DepartureWatch", "SIGHTINGS"]

#: Checks in a row without a client, after one was seen, that make its kind's clients gone.
SIGHTINGS = 2


class DepartureWatch:
    """Per kind: seen since its requests became active, and checks without a client since."""

    def __init__(self, kinds: Iterable[Hashable]):
        self._seen = {kind: False for kind in kinds}
        self._absent = {kind: 0 for kind in self._seen}

    def check(self, kind: Hashable, active: bool, present: bool) -> tuple[bool, bool]:
        """One check of ``kind``: ``active`` whether it has requests queued or running,
        ``present`` whether the graph holds a client of it. Returns (first sighting since
        its requests became active, its clients gone: cancel its requests)."""
        seen = active and (self._seen[kind] or present)
        first = seen and not self._seen[kind]
        self._seen[kind] = seen
        self._absent[kind] = self._absent[kind] + 1 if seen and not present else 0
        return first, self._absent[kind] >= SIGHTINGS
