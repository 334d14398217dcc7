"""The pure core of the scene objects' adoption (sim_peer.replica.adoption_rule): one wait at a time after sims leave, no
departure lost, and exactly one adopter among the shards. Unit tests, then property tests over random departures
and random worlds."""

from __future__ import annotations

from hypothesis import given, settings, strategies as hs

from sim_peer.replica import adoption_rule as ar


def test_a_departure_starts_one_wait_and_a_second_joins_it():
    w, start = ar.departed(ar.Watch(), serves_objects=False)
    assert start and w == ar.Watch(running=True, again=True)
    w, start = ar.departed(w, serves_objects=False)
    assert not start and w.running


def test_the_wait_looks_once_per_batch_of_departures_then_ends():
    w, _ = ar.departed(ar.Watch(), serves_objects=False)
    w, look = ar.waited(w, serves_objects=False)
    assert look and w == ar.Watch(running=True, again=False)
    w, look = ar.waited(w, serves_objects=False)  # nobody left since: the wait ends
    assert not look and w == ar.Watch()


def test_a_look_that_went_unanswered_looks_again_after_the_next_wait():
    w, _ = ar.departed(ar.Watch(), serves_objects=False)
    w, look = ar.waited(w, serves_objects=False)
    w = ar.unanswered(w)  # nobody answered srv/world in time
    w, look = ar.waited(w, serves_objects=False)
    assert look and w.running  # before: the wait ended, and nobody adopted the objects
    w, look = ar.waited(w, serves_objects=False)  # answered this time: nobody left since, the wait ends
    assert not look and w == ar.Watch()


def test_a_sim_that_serves_the_objects_neither_waits_nor_looks():
    assert ar.departed(ar.Watch(), serves_objects=True) == (ar.Watch(), False)
    w, _ = ar.departed(ar.Watch(), serves_objects=False)
    assert ar.waited(w, serves_objects=True) == (ar.Watch(), False)  # it took them over meanwhile


def test_a_closing_host_ends_the_wait_and_keeps_the_departure():
    assert ar.stopped(ar.Watch(running=True, again=True)) == ar.Watch(running=False, again=True)


def test_the_lowest_id_sim_adopts_when_no_part_describes_objects():
    parts = {"sim-b": False, "sim-a": False}
    assert ar.adopter(parts, "sim-a", has_objects=True)
    assert not ar.adopter(parts, "sim-b", has_objects=True)
    assert not ar.adopter({"sim-a": False, "sim-c": True}, "sim-a", has_objects=True)  # sim-c serves them
    assert not ar.adopter(parts, "sim-a", has_objects=False)  # a world without objects
    assert not ar.adopter({"sim-b": False}, "sim-a", has_objects=True)  # sim-a is not among those answering
    assert ar.wait_s(2.0) == 5.0


@settings(max_examples=100, deadline=None)
@given(hs.lists(hs.tuples(hs.sampled_from(["departed", "waited", "stopped"]), hs.booleans()), max_size=60))
def test_property_one_wait_at_a_time_and_no_departure_lost(events):
    """Random departures, waits ending and closes, the sim serving the objects or not: at most one wait runs; a
    departure seen while not serving the objects is looked at by the next wait's end, unless the sim serves them
    by then; a wait that runs on always has a look behind it."""
    w, threads, pending = ar.Watch(), 0, False
    for what, serves in events:
        if what == "departed":
            w, start = ar.departed(w, serves_objects=serves)
            assert not (start and threads)
            threads += start
            pending = pending or not serves
        elif what == "waited" and threads:
            w, look = ar.waited(w, serves_objects=serves)
            assert look == (pending and not serves)
            threads = 1 if look else 0
            pending = False  # looked at, or the sim serves the objects now
        elif what == "stopped" and threads:
            w, threads = ar.stopped(w), 0
        assert threads <= 1 and w.running == bool(threads)
        assert w.again == pending


@settings(max_examples=100, deadline=None)
@given(hs.dictionaries(hs.sampled_from(["sim-a", "sim-b", "sim-c", "sim-d"]), hs.booleans()), hs.booleans())
def test_property_exactly_one_shard_adopts_an_orphaned_world_and_none_a_served_one(parts, has_objects):
    adopters = [me for me in parts if ar.adopter(parts, me, has_objects=has_objects)]
    orphaned = has_objects and bool(parts) and not any(parts.values())
    assert len(adopters) == (1 if orphaned else 0)
    assert all(a == min(parts) for a in adopters)
