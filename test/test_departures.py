"""The departed-client watch's rule (grasp_apso/ros/departures.py): a kind's clients are
gone only after the graph showed one while its requests were active, then none on two
checks in a row. The node's use of it over DDS: test_node_process.py (a client that leaves)."""

from grasp_apso.ros.departures import SIGHTINGS, DepartureWatch
from grasp_apso.ros.plan_request import RequestKind


def _run(checks, kind=RequestKind.SERVICE):
    """(active, present) per check -> [(first sighting, gone), ...]."""
    watch = DepartureWatch(RequestKind)
    return [watch.check(kind, active, present) for active, present in checks]


def test_a_client_the_graph_has_not_shown_yet_is_not_taken_for_gone():
    # a fresh client's request arrives before the graph shows it: the old rule cancelled here
    out = _run([(True, False)] * 10 + [(True, True)])
    assert not any(gone for _, gone in out)
    assert [first for first, _ in out] == [False] * 10 + [True]


def test_seen_then_gone_on_the_second_check_in_a_row():
    assert SIGHTINGS == 2
    out = _run([(True, True), (True, True), (True, False), (True, False)])
    assert [gone for _, gone in out] == [False, False, False, True]
    assert [first for first, _ in out] == [True, False, False, False]


def test_a_reconnect_blip_is_not_a_departure():
    out = _run([(True, True), (True, False), (True, True), (True, False), (True, True)])
    assert not any(gone for _, gone in out)


def test_each_activation_needs_its_own_sighting():
    # requests end (inactive), then new ones come from a client the graph does not show yet
    out = _run([(True, True), (False, False), (True, False), (True, False), (True, False)])
    assert not any(gone for _, gone in out)
    assert [first for first, _ in out] == [True, False, False, False, False]


def test_kinds_are_watched_apart():
    watch = DepartureWatch(RequestKind)
    for _ in range(3):
        assert watch.check(RequestKind.ACTION, True, False) == (False, False)
    watch.check(RequestKind.SERVICE, True, True)
    watch.check(RequestKind.SERVICE, True, False)
    assert watch.check(RequestKind.SERVICE, True, False) == (False, True)
    assert watch.check(RequestKind.ACTION, True, False) == (False, False)
