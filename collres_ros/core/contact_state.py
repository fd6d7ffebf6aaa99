"""Per-body "in contact" state with hysteresis, from the solved contacts of each step.

A contact sensor for controllers (a foot's touchdown, a gripper's grasp): a body is in
contact once the normal impulses on it in one step sum to more than ``on_impulse``
(N s, > 0), and out of contact again only after ``off_steps`` steps in a row at or below
it, so the state does not chatter while a body bounces or slides over an edge. A
speculative contact that carries no impulse is not a touch. Impulses, not forces: the
caller states the threshold for its step length (a 1 kg box at rest at 100 Hz takes
m g dt = 0.098 N s a step).
"""

from __future__ import annotations

import numpy as np

from collres_ros.core.types import ContactReport


def body_normal_impulses(report: ContactReport, count: int) -> np.ndarray:
    """(count,) N s: the sum of the normal impulses of every contact each body takes part in."""
    if report.contacts.count == 0:
        return np.zeros(count)
    impulse = np.asarray(report.normal_impulse, float)
    return (np.bincount(report.contacts.body_a, impulse, count)
            + np.bincount(report.contacts.body_b, impulse, count))


class ContactStates:
    """The debounced in-contact state of ``count`` bodies (all out of contact at first)."""

    def __init__(self, count: int, on_impulse: float, off_steps: int) -> None:
        if not on_impulse > 0.0 or off_steps < 1:
            raise ValueError('contact state: on_impulse > 0 N s and off_steps >= 1 needed')
        self.on_impulse = float(on_impulse)
        self.off_steps = int(off_steps)
        self.in_contact = np.zeros(count, bool)
        self._quiet = np.zeros(count, np.int64)   # steps in a row without a touch

    def update(self, report: ContactReport) -> np.ndarray:
        """Take one step's solved contacts; the indices of the bodies whose state changed."""
        touched = body_normal_impulses(report, self.in_contact.size) > self.on_impulse
        self._quiet = np.where(touched, 0, self._quiet + 1)
        now = touched | (self.in_contact & (self._quiet < self.off_steps))
        changed = np.flatnonzero(now != self.in_contact)
        self.in_contact = now
        return changed
