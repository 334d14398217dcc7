"""When a run with ``until`` ends (:func:`robofabric.soak.run.after_look`): a catch ends it only once the next look
agrees; one taken back lets it go on to its planned end. Pure: the times are passed in."""

from __future__ import annotations

from robofabric.soak.run import UNTIL_AFTER_S, UNTIL_CHECK_S, after_look

PLANNED = 180.0


def test_a_catch_is_looked_at_once_more_before_the_run_ends():
    end, caught, said = after_look(True, False, 10.0, PLANNED, PLANNED)
    assert caught and end == 10.0 + UNTIL_CHECK_S + UNTIL_AFTER_S and said.startswith("broken")
    # the next look, with the lines written meanwhile, still finds it: the run ends as before, soon after
    end, caught, said = after_look(True, True, 10.0 + UNTIL_CHECK_S, end, PLANNED)
    assert caught and end == 10.0 + UNTIL_CHECK_S + UNTIL_AFTER_S and said.startswith("still broken")


def test_a_catch_the_fuller_history_takes_back_lets_the_run_go_on_to_its_planned_end():
    """Run 6 of the twenty-fourth session: the planted stale command's run ended 10 s in on a catch in the history
    read so far, and the whole history's verdict found nothing: the plant's test failed."""
    end, caught, _ = after_look(True, False, 10.0, PLANNED, PLANNED)
    end, caught, said = after_look(False, caught, 10.0 + UNTIL_CHECK_S, end, PLANNED)
    assert not caught and end == PLANNED and "going on" in said
    # and a later catch is judged the same way
    end, caught, _ = after_look(True, caught, 60.0, end, PLANNED)
    assert caught and end == 60.0 + UNTIL_CHECK_S + UNTIL_AFTER_S


def test_nothing_broken_changes_nothing_and_a_catch_never_ends_a_run_past_its_plan():
    assert after_look(False, False, 10.0, PLANNED, PLANNED) == (PLANNED, False, "")
    end, caught, _ = after_look(True, False, PLANNED - 1.0, PLANNED, PLANNED)
    assert caught and end == PLANNED
