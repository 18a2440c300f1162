"""The node's request queue without a ROS graph: coalescing, which estimate serves a request,
the mass of a state's time, the wait for an estimate that has not arrived yet."""
import threading
import time

import pytest

from daddy_ros.checks import InputRejected
from daddy_ros.request_queue import RequestQueue


def test_requests_during_a_solve_are_coalesced_into_the_newest():
    q = RequestQueue(estimate_wait_s=0.0)
    q.add_state([1, 0, 0], [0, 1, 0], 10.0)
    q.add_mass(10.0, 900.0)
    assert q.enqueue("a", 10.0) == 1 and q.coalesced == 0
    first = q.take()
    assert first.request_id == "a" and q.started == 1
    # while "a" is being solved, three more arrive: each replaces the waiting one
    for rid in ("b", "c", "d"):
        assert q.enqueue(rid, 10.0) == 2
    assert q.coalesced == 3
    q.record("report of a")
    q.done()
    nxt = q.take()
    assert nxt.request_id == "d" and q.started == 2 and q.finished == 1
    assert q.running(2) and not q.waiting(2) and q.report_of(2) is None
    q.record("report of d")
    q.done()
    assert not q.running(2) and q.report_of(1) == "report of a" and q.report_of(2) == "report of d"


def test_a_request_s_options_travel_with_it_and_the_newest_wins_when_coalesced():
    q = RequestQueue(estimate_wait_s=0.0)
    q.add_state([1, 0, 0], [0, 1, 0], 10.0)
    q.add_mass(10.0, 900.0)
    q.enqueue("a", None, cold=True, time_budget_s=5.0)
    assert q.waiting(1)
    q.enqueue("b", None, cold=False, time_budget_s=2.0)
    req = q.take()
    assert (req.request_id, req.cold, req.time_budget_s) == ("b", False, 2.0)


def test_the_estimate_for_a_request_and_the_mass_of_its_time():
    q = RequestQueue()
    assert q.state_for(None) is None and q.mass_sample_for(5.0) is None
    for t in (10.0, 20.0, 30.0):
        q.add_state([t, 0, 0], [0, 0, 0], t)
        q.add_mass(t, 1000.0 - t)
    assert q.state_for(None).stamp_s == 30.0                 # the service: the newest
    assert q.state_for(20.5).stamp_s == 20.0                 # the newest not after the request
    assert q.state_for(19.2).stamp_s == 20.0                 # ... within FUTURE_TOLERANCE_S
    with pytest.raises(InputRejected, match="future of the request stamp"):
        q.state_for(1.0)
    assert q.mass_sample_for(20.0) == (20.0, 980.0) and q.mass_sample_for(25.0) == (20.0, 980.0)
    assert q.mass_sample_for(5.0) == (30.0, 970.0)              # none before: the newest


def test_a_request_waits_for_the_estimate_of_its_time_then_its_queue_time_counts():
    q = RequestQueue(estimate_wait_s=2.0)
    q.add_state([1, 0, 0], [0, 0, 0], 10.0)
    q.add_mass(10.0, 900.0)
    q.enqueue("late", 50.0)                       # stamped after every estimate so far
    threading.Timer(0.3, lambda: (q.add_mass(50.0, 899.0), q.add_state([2, 0, 0], [0, 0, 0],
                                                                        50.0))).start()
    t0 = time.monotonic()
    req = q.take()
    waited = time.monotonic() - t0
    assert 0.2 < waited < 1.9                     # until the estimate came, not the whole wait
    assert req.stamp_s >= 50.0 + 0.2              # its mission time includes the queue wait
    assert q.state_for(req.stamp_s).stamp_s == 50.0


def test_stop_releases_the_worker_and_waiting_callers():
    q = RequestQueue()
    got = []
    th = threading.Thread(target=lambda: got.append(q.take()))
    th.start()
    q.stop()
    th.join(2.0)
    assert got == [None]
    assert q.stopped() and not q.waiting(1)
