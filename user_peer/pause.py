"""A waited command rides out a sim that holds its robots: a pause, not a refusal.

A sim that was cut off from its world, or that froze and is not yet sure of its link, holds its robots and refuses
every command with code ``held`` (:mod:`sim_peer.replica.deaf_stop`) until it hears again, usually within a second or two.
A command given with ``wait=True`` (:meth:`user_peer.arm.Arm.move_joints`, :meth:`user_peer.mobile_base.Base.follow`)
must not fail for that: :class:`PauseRider` watches the robot's refusals while the command is awaited, raises any
other refusal at once, and on a hold (a refusal of the command, the sim's word, once it hears again, that the hold
stopped the robot before the command was done, or a sim's token come back: one cut off never had what was sent
meanwhile) sends the same command again (the same envelope: its id and its epoch,
:meth:`user_peer.robot.Robot.resend`) until the sim takes it, all within the command's own timeout. The sim applies
a command once by its id (:mod:`sim_peer.serving.command_ids`), so a copy that arrives after the first was taken changes
nothing. A hand-over meanwhile (the epoch changed) ends the ride with :class:`~user_peer.errors.NotOwner`.

The sim reports its refusals a few times per second at most (:mod:`fabric.reports`), so the rider cannot count on
one answer per copy: it sends again at growing intervals (:data:`RESEND_S` to :data:`RESEND_MAX_S`) while a hold was
reported within :data:`QUIET_S`, and then every :data:`RESEND_MAX_S` until the command's wait ends. A copy the sim
refused while it held may be the last one it reported for seconds (its limit of refusals per interval was spent on
earlier copies), and its word that it hears again may arrive before its token does (an event from a sim not yet
back is no authority's): a rider that stopped at the last report it trusted lost the command (CI, a 3 s pause).
A copy after the first was taken costs one message a second and changes nothing (the sim's ids).

A robot can also be taken from its owner and given back while she waits: the authority held her for gone (her token
went with a link of the sim's, and came back within her grace) and passed the robot on, free, which stopped it; back,
she owns it under a new epoch, at which the sim refuses the first copy. A rider of a command that ends where it ends
(``resend_on_takeover``: joint targets) gives it again under her new epoch (a new command, the same body), once per
epoch: the move a user still waits for is hers to finish (a CI run's move timed out 28 deg off, owned by her again).
Any command the sim refused for an epoch of hers that is past, while the robot is hers again, is given again so too:
it was never taken (the paused student, woken, sent his path under the epoch his replica still had: "stale epoch 1
for base1 (current 3)", and his Test B failed).

A command can also be lost with no pause at all: a sim that has just started may not yet be known to the router as
a listener of its commands, and the first one is put to nobody (the lab's clock-skew scenario: the new sim counted
0 commands and alice's move timed out 17 deg off). A rider given a ``heard`` test (the robot shows a sign of the
command: an arm or a base moving, or already there) sends the command again every :data:`RESEND_MAX_S` from
:data:`UNHEARD_S` after it was given until that sign comes.
"""

from __future__ import annotations

import time
from typing import TYPE_CHECKING, Any, Callable

from fabric.interfaces import REJECT_KINDS, Command, Event
from user_peer.errors import NotOwner, Paused
from user_peer.robot import HELD, RESUMED, rejection_error

if TYPE_CHECKING:
    from user_peer.robot import Robot

__all__ = ["PauseRider", "RESEND_S", "RESEND_MAX_S", "QUIET_S", "UNHEARD_S", "is_pause", "pause_words"]

RESEND_S = 0.2
"""The first resend after a hold was seen; each next one waits twice as long, up to :data:`RESEND_MAX_S`."""
RESEND_MAX_S = 1.0
QUIET_S = 2.0
"""Resends stop when no hold was reported this long (the sim took the command, or a copy of it)."""
UNHEARD_S = 1.0
"""A command whose robot shows no sign of it this long after it was given is sent again (a sim's state streams at
50 Hz, and a taken arm target moves the arm within a step: a second is twenty states with no sign)."""


def is_pause(ev: Event) -> bool:
    """Whether ``ev`` is a sim's ``held`` refusal: a pause, which the console and the ROS 2 bridge show as such."""
    return ev.kind in REJECT_KINDS and isinstance(ev.data, dict) and ev.data.get("code") in (HELD, RESUMED)


def pause_words(robot: str, ev: Event | None = None) -> str:
    """What a client shows for a pause of ``robot``'s sim (the hold ``ev`` told of), instead of an error: the sim's
    word once it hears again (code ``resumed``) reads as the end of the pause."""
    if ev is not None and isinstance(ev.data, dict) and ev.data.get("code") == RESUMED:
        return (
            f"the sim was paused and hears again: {robot} stopped before its command was done (a waiting command "
            "is sent again; one sent without waiting may be sent again)"
        )
    return (
        f"the sim is paused: {robot} holds until its sim hears its router again (a waiting command is sent "
        "again then; one sent without waiting may be sent again)"
    )


class PauseRider:
    """The refusals of one awaited command ``cmd`` (sent as ``command`` to ``robot`` after event mark ``since``)."""

    def __init__(
        self,
        robot: "Robot",
        command: str,
        cmd: Command,
        since: int,
        clock: Callable[[], float] = time.monotonic,
        *,
        resend_on_takeover: bool = False,
        heard: Callable[[], bool] | None = None,
    ) -> None:
        self.robot, self.command, self.cmd, self.since = robot, command, cmd, since
        self.clock = clock
        # a command that ends where it ends however often it is taken (joint targets, not a path to drive from its
        # start) is sent again when a standby takes the robot over (a higher term in its joints): the sim that died
        # may have had it, unmirrored, when it went (the two-SIGKILL failover test lost a target so)
        self.resend_on_takeover = resend_on_takeover
        self.term = self._term()
        self.seen = 0  # refusals since the mark already judged
        self.holds = 0  # holds reported
        self.resends = 0
        self.last_hold = float("-inf")
        self.sent_at = float("-inf")
        self.interval = RESEND_S
        self.arrivals = robot.world.presence.arrivals
        self.heard = heard  # None: no sign to wait for; else copies go only until a sign came
        self.given_at = clock()
        self.unheard = 0  # copies sent because the robot showed no sign of the command
        self.regiven = 0  # commands given again under the owner's new epoch (the robot taken from her and given back)

    def check(self) -> None:
        """Raise any refusal but a hold (:class:`~user_peer.errors.NotOwner`, :class:`~user_peer.errors.Rejected`);
        on a hold, send the command again when it is time. Called while the command is awaited."""
        rej = self.robot.world.rejections(self.robot.id, self.since)
        now = self.clock()
        for ev in rej[self.seen :]:
            err = rejection_error(self.robot.id, ev)
            if isinstance(err, NotOwner) and self._refused_at_a_past_epoch():
                continue  # hers again under a newer epoch: given again (or was already), see the module
            if not isinstance(err, Paused):
                raise err
            if now - self.last_hold > QUIET_S:
                self.interval = RESEND_S  # a new pause: send at once, then at growing intervals
                self.sent_at = float("-inf")
            self.last_hold = now
            self.holds += 1
        self.seen = len(rej)
        arrivals = self.robot.world.presence.arrivals
        if arrivals != self.arrivals:  # a sim's token came back: it was cut off, and may never have had the command
            self.arrivals = arrivals
            self.interval, self.sent_at, self.last_hold = RESEND_S, float("-inf"), now
        if self.resend_on_takeover:
            self._given_back()
        term = self._term() if self.resend_on_takeover else self.term
        if term > self.term:  # a standby took the robot over: it may never have had the command
            self.term = term
            self.interval, self.sent_at, self.last_hold = RESEND_S, float("-inf"), now
        paused = now - self.last_hold <= QUIET_S  # a hold reported lately: copies at growing intervals
        after = self.last_hold > float("-inf")  # a pause met this command: a copy every RESEND_MAX_S till it is done
        if (paused and now - self.sent_at >= self.interval) or (after and now - self.sent_at >= RESEND_MAX_S):
            self._copy()
            self.resends += 1
            self.sent_at = now
            self.interval = min(2 * self.interval, RESEND_MAX_S)
        elif self.heard is not None:
            if self.heard():
                self.heard = None  # a sign came: the sim has the command; pauses alone send copies from now on
            elif now - self.given_at >= UNHEARD_S and now - self.sent_at >= RESEND_MAX_S:
                self._copy()
                self.resends += 1
                self.unheard += 1
                self.sent_at = now

    def _copy(self) -> None:
        """Send the command again; given again under her epoch instead when the robot is hers under a newer one (a
        copy at the past epoch could only be refused, and ``resend`` raises on it). The sim's refusal of a copy says
        so too (:meth:`_refused_at_a_past_epoch`), but a copy may be due first: the paused student's sim came back
        (its token) as base1 came back to him at epoch 3, and the copy raised "changed hands" (2026-12-04)."""
        if not self._given_back():
            self.robot.resend(self.command, self.cmd)

    def _given_back(self, rec: Any = None) -> bool:
        """Give the command again under the owner's epoch when the robot came back to her (see the module); whether
        it was given again."""
        rec = rec if rec is not None else getattr(self.robot, "record", None)
        if rec is None or rec.owner != self.robot.world.user or rec.epoch <= self.cmd.epoch:
            return False
        self.cmd = self.robot.send(self.command, self.cmd.body, epoch=rec.epoch)
        self.regiven += 1
        self.given_at = self.clock()  # its copies count from now (a sign is awaited only where none came of the first)
        self.sent_at = self.given_at
        return True

    def _refused_at_a_past_epoch(self) -> bool:
        """After an ownership refusal: whether the robot is hers now under an epoch newer than the one it refused (she
        was held for gone and given it back; her replica, just woken, still had the old one). The command is then
        given again under her epoch, whatever it is (one refused was never taken); a refusal of a copy sent before it
        was given again changes nothing. Else the refusal stands. The authority is asked when the replica is behind."""
        user = self.robot.world.user
        rec = getattr(self.robot, "record", None)
        if rec is None or rec.owner != user or rec.epoch <= self.cmd.epoch:
            ownership = getattr(self.robot.world, "ownership", None)
            if ownership is not None:
                rec = ownership.fetch(self.robot.id, timeout=1.0)
        if rec is None or rec.owner != user:
            return False
        return self._given_back(rec) or (self.regiven > 0 and rec.epoch == self.cmd.epoch)

    def _term(self) -> int:
        js = self.robot.latest("joints")
        header = getattr(js, "header", None)
        return int(getattr(header, "term", 0) or 0)

    def note(self) -> str:
        """Words for a timeout's message: how the pause went ('' : there was none)."""
        unheard = f"; no sign of the command came, and it was sent again {self.unheard} time(s)" if self.unheard else ""
        if self.regiven:
            unheard += f"; the robot was taken from its owner and given back, and the command given again {self.regiven} time(s)"
        if not self.holds:
            return unheard
        return (
            unheard
            + f"; the sim held its robots (a pause) {self.holds} time(s) meanwhile and the command was sent again {self.resends} time(s)"
        )
